"""Shapes: immutable CSG trees built in Python and evaluated by the pruned C++ engine.

A Shape is a value: transforms and operators return new shapes and never change their operands.
The tree is handed to the engine (SceneBuilder, via the extension module) when a query needs it;
the built scene and pruned grids are cached on the shape.
"""
from __future__ import annotations

import math
import numbers
import os
from typing import TYPE_CHECKING, Any, Optional, Sequence, Tuple, Union

from . import _sdfprune as _core
from ._inputs import _MESH_EXTS, _SAVE_EXTS, _check_ext, _points
from ._progress import progress_callback

if TYPE_CHECKING:  # numpy is imported on first use: `import sdfprune` stays fast
    import numpy as np

    from ._grid import PrunedGrid

Vec3 = Tuple[float, float, float]
# Scenes with at most this many nodes answer f(points) with the whole tree by default: it costs
# about what a lookup in the pruned grid costs, and every value is exact.
EXACT_NODES = 64
# Sub-box refinement for queries that evaluate each cell once (discretize, mesh, saving a mesh,
# .npy or .vdb): off, as in the CLI's discretize and mesh. It spends pruning time to make later
# queries cheaper, which a single pass over the cells cannot win back.
ONE_SHOT_REFINE = 1
Bounds = Tuple[Sequence[float], Sequence[float]]

X = (1.0, 0.0, 0.0)
Y = (0.0, 1.0, 0.0)
Z = (0.0, 0.0, 1.0)
ORIGIN = (0.0, 0.0, 0.0)

_IDENTITY = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)


# ---- 3x4 affine maps as 12-tuples (row-major), local -> world -------------------------------

def _is_number(x: Any) -> bool:
    return isinstance(x, numbers.Number) or getattr(x, "ndim", None) == 0


def _vec3(v: Any, what: str) -> Vec3:
    if _is_number(v) or isinstance(v, (str, bytes)):
        raise ValueError(f"{what} must be a 3-vector")
    t = tuple(float(x) for x in v)
    if len(t) != 3:
        raise ValueError(f"{what} must be a 3-vector (got {len(t)} numbers)")
    if not all(math.isfinite(x) for x in t):
        raise ValueError(f"{what} must be finite")
    return t  # type: ignore[return-value]


def _compose(a, b):
    """a after b."""
    r = [0.0] * 12
    for i in range(3):
        for j in range(3):
            r[4 * i + j] = sum(a[4 * i + k] * b[4 * k + j] for k in range(3))
        r[4 * i + 3] = sum(a[4 * i + k] * b[4 * k + 3] for k in range(3)) + a[4 * i + 3]
    return tuple(r)


def _rotation(axis: Vec3, angle: float):
    x, y, z = axis
    n = math.sqrt(x * x + y * y + z * z)
    if not n > 0:
        raise ValueError("rotation axis must be non-zero")
    x, y, z = x / n, y / n, z / n
    c, s = math.cos(angle), math.sin(angle)
    t = 1 - c
    return (t * x * x + c, t * x * y - s * z, t * x * z + s * y, 0.0,
            t * x * y + s * z, t * y * y + c, t * y * z - s * x, 0.0,
            t * x * z - s * y, t * y * z + s * x, t * z * z + c, 0.0)


def _orientation(axis: Vec3):
    """The rotation taking +y (the primitives' axis) onto `axis`."""
    x, y, z = axis
    n = math.sqrt(x * x + y * y + z * z)
    if not n > 0:
        raise ValueError("orient: axis must be non-zero")
    x, y, z = x / n, y / n, z / n
    if y > 1 - 1e-12:
        return _IDENTITY
    if y < -1 + 1e-12:
        return _rotation(X, math.pi)
    # axis = y × target = (z, 0, -x); angle = acos(y)
    return _rotation((z, 0.0, -x), math.acos(max(-1.0, min(1.0, y))))


def _color(rgb: Any) -> Vec3:
    c = _vec3(rgb, "color")
    if not all(0.0 <= v <= 1.0 for v in c):
        raise ValueError("color components must be in [0, 1]")
    return c


def _bounds(bounds: Any) -> Optional[Tuple[Vec3, Vec3]]:
    if bounds is None:
        return None
    try:
        lo, hi = bounds
    except (TypeError, ValueError):
        raise ValueError("bounds must be ((x0, y0, z0), (x1, y1, z1))") from None
    lo, hi = _vec3(lo, "bounds"), _vec3(hi, "bounds")
    if not all(a < b for a, b in zip(lo, hi)):
        raise ValueError("bounds must have min < max on every axis")
    return lo, hi


# ---- the tree -----------------------------------------------------------------------------
# Nodes are tuples: ("prim", kind, fields, color | None), ("op", kind, a, b, k),
# ("place", child, affine12), ("color", child, rgb), ("scene", _core.Scene).

def _steps(root) -> list:
    """Post-order list of build steps (children as indices); iterative, so any depth works.
    A node used twice is emitted once (the engine duplicates it when flattening)."""
    steps: list = []
    index: dict = {}
    stack = [(root, False)]
    while stack:
        node, ready = stack.pop()
        key = id(node)
        if key in index:
            continue
        tag = node[0]
        if tag == "op":
            children = (node[2], node[3])
        elif tag in ("place", "color"):
            children = (node[1],)
        else:
            children = ()
        if not ready and children:
            stack.append((node, True))
            for c in reversed(children):
                if id(c) not in index:
                    stack.append((c, False))
            continue
        if tag == "op":
            steps.append(("op", node[1], index[id(node[2])], index[id(node[3])], node[4]))
        elif tag == "place":
            steps.append(("place", index[id(node[1])], node[2]))
        elif tag == "color":
            steps.append(("color", index[id(node[1])], node[2]))
        else:
            steps.append(node)
        index[key] = len(steps) - 1
    return steps


class Shape:
    """A signed distance field: primitives combined by CSG operators (negative inside).

    Build shapes with the primitive functions (sphere, box, ...), move them with translate,
    scale, rotate and orient, combine them with | (union), & (intersection), - (difference)
    or union/intersection/difference(..., k=...) for smooth blends. Query them with
    f(points), f.discretize(), f.mesh(), f.render(), f.save(path); f.prune(grid) gives a pruned
    grid reusable for many queries. Shapes are immutable; the built scene and pruned grids are
    cached on each shape.
    """

    __slots__ = ("_node", "_bounds", "_k", "_cache", "__weakref__")

    def __init__(self, node, bounds=None, k: Optional[float] = None):
        self._node = node
        self._bounds = bounds
        self._k = k
        self._cache: dict = {}

    # ---- transforms ----
    def _placed(self, m) -> "Shape":
        node = self._node
        if node[0] == "place":
            node = ("place", node[1], _compose(m, node[2]))
        else:
            node = ("place", node, m)
        return Shape(node, None, self._k)

    def translate(self, offset: Sequence[float]) -> "Shape":
        """The shape moved by `offset` (x, y, z)."""
        x, y, z = _vec3(offset, "offset")
        return self._placed((1.0, 0.0, 0.0, x, 0.0, 1.0, 0.0, y, 0.0, 0.0, 1.0, z))

    def scale(self, factor: Union[float, Sequence[float]]) -> "Shape":
        """The shape scaled about the origin: uniformly by a number, or per axis by (sx, sy, sz).

        As in the scene format, the field of the scaled shape at p is the unscaled field at the
        mapped point: the surface is exact, values are divided by the scale (a uniform scale s
        gives a field with Lipschitz bound 1/s, which pruning accounts for). To keep true
        distances, scale the primitives' own sizes instead."""
        if _is_number(factor):
            s = (float(factor),) * 3  # type: ignore[arg-type]
        else:
            s = _vec3(factor, "scale")
        if not all(math.isfinite(v) and v != 0 for v in s):
            raise ValueError("scale factors must be finite and non-zero")
        return self._placed((s[0], 0.0, 0.0, 0.0, 0.0, s[1], 0.0, 0.0, 0.0, 0.0, s[2], 0.0))

    def rotate(self, angle: float, axis: Sequence[float] = Z) -> "Shape":
        """The shape rotated by `angle` radians (counter-clockwise) about `axis` through the
        origin."""
        angle = float(angle)
        if not math.isfinite(angle):
            raise ValueError("angle must be finite")
        return self._placed(_rotation(_vec3(axis, "axis"), angle))

    def orient(self, axis: Sequence[float]) -> "Shape":
        """The shape rotated so that its +y axis (the axis of cylinders, cones, capsules and
        the normal of tori) points along `axis`: c.orient(X), c.orient(Z)."""
        return self._placed(_orientation(_vec3(axis, "axis")))

    def color(self, r: Union[float, Sequence[float]], g: Optional[float] = None,
              b: Optional[float] = None) -> "Shape":
        """The shape with every primitive colored (r, g, b), components in [0, 1]."""
        rgb = _color(r if g is None and b is None else (r, g, b))
        return Shape(("color", self._node, rgb), self._bounds, self._k)

    def k(self, k: float) -> "Shape":
        """The same shape, blended with radius k by the next operator it is the right-hand
        operand of (fogleman/sdf's convention: a | b.k(0.1) is a smooth union)."""
        return Shape(self._node, self._bounds, _blend(k))

    def bounded(self, bounds: Bounds) -> "Shape":
        """The same shape over explicit bounds ((x0, y0, z0), (x1, y1, z1)), used by queries
        that need a region (discretize, mesh, render, prune) instead of the shape's own box."""
        return Shape(self._node, _bounds(bounds), self._k)

    # ---- operators ----
    def __or__(self, other: "Shape") -> "Shape":
        return union(self, other)

    def __and__(self, other: "Shape") -> "Shape":
        return intersection(self, other)

    def __sub__(self, other: "Shape") -> "Shape":
        return difference(self, other)

    # ---- the engine's view ----
    def scene(self, bounds: Optional[Bounds] = None):
        """The built engine scene (cached): over `bounds`, else the shape's bounds (a loaded
        scene's own AABB, or a box around the primitives padded by 5 %)."""
        b = _bounds(bounds) if bounds is not None else self._bounds
        key = ("scene", b)
        s = self._cache.get(key)
        if s is None:
            if self._node[0] == "scene":
                s = self._node[1] if b is None else self._node[1].with_aabb(b)
            else:
                s = _core.build_scene(_steps(self._node), b)
            self._cache[key] = s
        return s

    @property
    def bounds(self) -> Tuple[Vec3, Vec3]:
        """The region queries cover: ((x0, y0, z0), (x1, y1, z1))."""
        return self.scene().aabb

    def info(self) -> dict:
        """Node counts, depth, bounds, ... (as `sdfprune info --json`)."""
        return self.scene().info()

    def to_json(self) -> str:
        """The scene in the reference JSON format."""
        return self.scene().to_json()

    def save_scene(self, path: Union[str, os.PathLike]) -> None:
        """Writes the scene in the reference JSON format (atomically), for the CLI or load()."""
        self.scene().save(os.fspath(path))

    def prune(self, grid: int = 256, *, backend: str = "cpu", bounds: Optional[Bounds] = None,
              far_field: bool = True, hierarchy: bool = True, far_field_c: float = 2.0,
              refine: int = 3, lipschitz_bounds: bool = False, factor: int = 4,
              clearance: bool = False, threads: int = 0,
              progress: Any = None) -> "PrunedGrid":
        """Prunes the shape over a grid³ grid (cached per options): a PrunedGrid reusable for
        many queries, with .stats (the figures of `sdfprune stats --json`).

        backend="vulkan" prunes on the GPU (when this build has the Vulkan backend; otherwise
        a GpuError, a RuntimeError, says so). far_field=False gives exact values everywhere
        (slower); clearance=True stores the far-field clearances that let rendering skip whole
        boxes of far-field cells (render() asks for them, as `sdfprune render`); the other
        options are the CLI's (--farfield-c, --refine, ...)."""
        from ._grid import PrunedGrid
        if backend not in ("cpu", "vulkan"):
            raise ValueError(f"backend must be 'cpu' or 'vulkan' (got {backend!r})")
        scene = self.scene(bounds)
        opts = (int(grid), bool(far_field), bool(hierarchy), float(far_field_c), int(refine),
                bool(lipschitz_bounds), int(factor), bool(clearance))
        key = ("grid", backend, scene.aabb, opts)
        g = self._cache.get(key)
        if g is None:
            if backend == "vulkan":
                core = _core.prune_gpu(scene, *opts)
            else:
                core = _core.prune(scene, *opts, int(threads), progress_callback(progress, "pruning"))
            g = PrunedGrid(self, scene, core, backend)
            self._cache[key] = g
        return g

    # ---- queries ----
    def __call__(self, points: Any, *, exact: Optional[bool] = None, grid: int = 256,
                 out=None, threads: int = 0, progress: Any = None) -> "np.ndarray":
        """The SDF at points: (N, 3) float32/float64 array-like in, (N,) float32 out (negative
        inside). float32 C-contiguous input is read in place (no copy).

        exact=False: through the pruned grid (self.prune(grid), as `sdfprune eval`): exact
        near the surface (cells within about 2 cell diagonals of it) and outside the bounds;
        elsewhere the far-field cell's conservative value (right sign, magnitude never above
        the distance: a safe sphere-tracing step). exact=True: the whole tree at every point,
        exact everywhere (slow on large scenes). Default (None): exact for scenes of at most
        EXACT_NODES (64) nodes, where it costs no more, else pruned."""
        if exact is None:
            exact = self.scene().nodes <= EXACT_NODES
        if exact:
            arr = _points(points)
            return _core.eval_scene(self.scene(), arr, out, int(threads),
                                    progress_callback(progress, "evaluating"))
        return self.prune(grid, threads=threads)(points, out=out, threads=threads,
                                                 progress=progress)

    def discretize(self, res: int = 256, bounds: Optional[Bounds] = None, *, exact: bool = False,
                   threads: int = 0, progress: Any = None) -> "np.ndarray":
        """The SDF at the centres of a res³ grid of cells over `bounds` (default: the shape's),
        an (res, res, res) float32 array indexed [z, y, x]. Pruned at grid = res: far-field
        cells hold their conservative bound; exact=True evaluates the whole tree everywhere."""
        if exact:
            return _core.discretize_scene(self.scene(bounds), int(res), int(threads),
                                          progress_callback(progress, "discretizing"))
        return self.prune(int(res), bounds=bounds, refine=ONE_SHOT_REFINE,
                          threads=threads).discretize(res, threads=threads, progress=progress)

    def mesh(self, res: int = 256, bounds: Optional[Bounds] = None, *, threads: int = 0,
             progress: Any = None) -> Tuple["np.ndarray", "np.ndarray"]:
        """The surface as (vertices (V, 3) float32, faces (F, 3) uint32): marching tetrahedra on
        res³ cubes over `bounds` (default: the shape's); closed, 2-manifold, faces
        counter-clockwise seen from outside."""
        res = int(res)
        return self.prune(_mesh_grid(res), bounds=bounds, refine=ONE_SHOT_REFINE,
                          threads=threads).mesh(res, threads=threads, progress=progress)

    def render(self, width: int = 640, height: int = 360, *, yaw: float = 30, pitch: float = 25,
               distance: Optional[float] = None, fov: float = 40,
               target: Optional[Sequence[float]] = None, shading: str = "shaded",
               shadows: bool = True, grid: int = 256, threads: int = 0,
               progress: Any = None) -> "np.ndarray":
        """A sphere-traced picture, (height, width, 3) uint8, with the CLI's camera: orbiting
        the bounds' centre (or `target`) at yaw/pitch degrees, `distance` (default: frames
        the bounds), vertical `fov` degrees; shading 'shaded', 'normals' or 'heatmap'."""
        return self.prune(grid, clearance=True, threads=threads).render(
            width, height, yaw=yaw, pitch=pitch, distance=distance, fov=fov, target=target,
            shading=shading, shadows=shadows, threads=threads, progress=progress)

    def save(self, path: Union[str, os.PathLike], *, res: int = 256,
             bounds: Optional[Bounds] = None, threads: int = 0, progress: Any = None,
             **render_options: Any) -> None:
        """Writes by extension, atomically (nothing is written on failure): .stl, .ply, .obj
        (mesh at res), .npy (discretized at res, [z, y, x]), .vdb (OpenVDB level set),
        .png (render; width, height and the camera as in render())."""
        path, ext = _check_ext(path, _SAVE_EXTS)
        if ext == ".png":
            grid = self.prune(render_options.pop("grid", 256), bounds=bounds, clearance=True,
                              threads=threads)
        else:
            grid_res = _mesh_grid(int(res)) if ext in _MESH_EXTS else int(res)
            grid = self.prune(grid_res, bounds=bounds, refine=ONE_SHOT_REFINE, threads=threads)
        grid.save(path, res=res, threads=threads, progress=progress, **render_options)

    def _repr_png_(self) -> bytes:
        from ._png import encode_png
        return encode_png(self.render(480, 270))

    def __repr__(self) -> str:
        try:
            i = self.info()
            return f"<sdfprune.Shape: {i['primitives']} primitives, {i['nodes']} nodes>"
        except Exception as e:  # an invalid tree still prints
            return f"<sdfprune.Shape (invalid: {e})>"


SDF3 = Shape


def _mesh_grid(res: int) -> int:
    """The pruning grid for a mesh at res (the engine's default_mesh_grid); a res out of range
    is passed on, so that the pruning's own check reports it."""
    return _core.default_mesh_grid(res) if 1 <= res <= 2048 else res


def _blend(k: Any) -> float:
    k = float(k)
    if not (math.isfinite(k) and k >= 0):
        raise ValueError(f"blend radius k must be >= 0 (got {k})")
    return k


def _shape(x: Any, what: str) -> Shape:
    if not isinstance(x, Shape):
        raise TypeError(f"{what} must be an sdfprune Shape (got {type(x).__name__})")
    return x


def _combine(kind: int, a: Shape, bs: Sequence[Shape], k: Optional[float]) -> Shape:
    out = _shape(a, "operand")
    for b in bs:
        b = _shape(b, "operand")
        kk = k if k is not None else (b._k if b._k is not None else out._k)
        out = Shape(("op", kind, out._node, b._node, _blend(kk or 0.0)))
    return out


def union(a: Shape, *bs: Shape, k: Optional[float] = None) -> Shape:
    """a ∪ b ∪ ...: min(a, b), smoothly blended over a radius k when k > 0
    (min(a, b) − max(k − |a − b|, 0)² / 4k). Without k, a right-hand operand's .k(...) is
    used."""
    return _combine(_core.OP_UNION, a, bs, k)


def intersection(a: Shape, *bs: Shape, k: Optional[float] = None) -> Shape:
    """a ∩ b ∩ ...: max(a, b), smoothly blended when k > 0."""
    return _combine(_core.OP_INTERSECTION, a, bs, k)


def difference(a: Shape, *bs: Shape, k: Optional[float] = None) -> Shape:
    """a minus b (minus ...): max(a, −b), smoothly blended when k > 0."""
    return _combine(_core.OP_DIFFERENCE, a, bs, k)


def load(path: Union[str, os.PathLike]) -> Shape:
    """A scene file in the reference JSON format (the CLI's), as a Shape over its own AABB.
    Raises OSError when the file cannot be read, ValueError when it is not a valid scene."""
    scene = _core.load_scene(os.fspath(path))
    return Shape(("scene", scene), scene.aabb)


def loads(text: str, name: str = "<string>") -> Shape:
    """A scene given as JSON text (see load)."""
    scene = _core.parse_scene(text, name)
    return Shape(("scene", scene), scene.aabb)


