"""PrunedGrid: a shape pruned over a grid, reusable for many queries (Shape.prune)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Optional, Sequence, Tuple

if TYPE_CHECKING:
    import numpy as np

from . import _sdfprune as _core
from ._progress import progress_callback
from ._inputs import _MESH_EXTS, _SAVE_EXTS, _check_ext, _points


class PrunedGrid:
    """A shape pruned over a grid³ grid of cells: per cell, a tape of the few nodes that
    matter there, or a far-field constant. Immutable and thread-safe; it keeps its scene alive.

    Queries: grid(points), grid.discretize(), grid.mesh(), grid.render(), grid.save(path).
    grid.stats holds the figures of `sdfprune stats --json` (on a GPU grid, with the device's
    and each step's, gpu_steps). A grid made with backend="vulkan"
    lives on the GPU and answers discretize, render and save(.npy/.vdb/.png) only.
    """

    __slots__ = ("shape", "_scene", "_core", "backend")

    def __init__(self, shape, scene, core, backend: str):
        self.shape = shape
        self._scene = scene
        self._core = core
        self.backend = backend

    @property
    def resolution(self) -> int:
        """Finest cells per axis."""
        return self._core.resolution

    @property
    def bounds(self):
        """The region the grid covers: ((x0, y0, z0), (x1, y1, z1))."""
        return self._scene.aabb

    @property
    def stats(self) -> dict:
        """Pruning statistics, the figures (and keys) of `sdfprune stats --json`: active_avg,
        active_std, active_max, near_field_cells, tape_avg, tape_max, prune_ms, ..."""
        return self._core.stats()

    def _cpu(self, what: str):
        if self.backend != "cpu":
            raise ValueError(f"{what} is not available on a backend='vulkan' grid; "
                             "prune with backend='cpu'")
        return self._core

    def __call__(self, points: Any, *, out: "Optional[np.ndarray]" = None, threads: int = 0,
                 progress: Any = None) -> "np.ndarray":
        """The pruned SDF at points, (N, 3) -> (N,) float32 (see Shape.__call__)."""
        return _core.eval_grid(self._cpu("evaluation at points"), _points(points), out,
                               int(threads), progress_callback(progress, "evaluating"))

    eval = __call__

    def discretize(self, res: Optional[int] = None, *, threads: int = 0,
                   progress: Any = None) -> "np.ndarray":
        """The pruned SDF at the centres of a res³ grid over the bounds (default: the grid's
        own resolution, the fastest), (res, res, res) float32 indexed [z, y, x]."""
        res = self.resolution if res is None else int(res)
        if self.backend == "vulkan":
            return _core.discretize_gpu(self._core, res)
        return _core.discretize_grid(self._core, res, int(threads),
                                     progress_callback(progress, "discretizing"))

    def mesh(self, res: Optional[int] = None, *, threads: int = 0,
             progress: Any = None) -> Tuple["np.ndarray", "np.ndarray"]:
        """(vertices (V, 3) float32, faces (F, 3) uint32) on res³ cubes (see Shape.mesh)."""
        res = self.resolution if res is None else int(res)
        return _core.mesh_grid(self._cpu("meshing"), res, int(threads),
                               progress_callback(progress, "meshing"))

    def render(self, width: int = 640, height: int = 360, *, yaw: float = 30, pitch: float = 25,
               distance: Optional[float] = None, fov: float = 40,
               target: Optional[Sequence[float]] = None, shading: str = "shaded",
               shadows: bool = True, threads: int = 0, progress: Any = None) -> "np.ndarray":
        """A sphere-traced picture on the pruned grid, (height, width, 3) uint8 (see
        Shape.render; the same camera as `sdfprune render`)."""
        return _core.render(self._core, int(width), int(height), float(yaw), float(pitch),
                            0.0 if distance is None else float(distance), float(fov), target,
                            str(shading), bool(shadows), int(threads),
                            progress_callback(progress, "tracing"))

    def save(self, path, *, res: Optional[int] = None, threads: int = 0, progress: Any = None,
             **render_options: Any) -> None:
        """Writes by extension, atomically (see Shape.save)."""
        path, ext = _check_ext(path, _SAVE_EXTS)
        if ext in _MESH_EXTS:
            res = self.resolution if res is None else int(res)
            _core.mesh_grid(self._cpu("meshing"), res, int(threads),
                            progress_callback(progress, "meshing"), path)
        elif ext == ".png":
            render_options.pop("grid", None)
            _core.write_png(path, self.render(threads=threads, progress=progress,
                                              **render_options))
        else:
            values = self.discretize(res, threads=threads, progress=progress)
            if ext == ".npy":
                _core.write_npy(path, values)
            else:
                _core.write_vdb(path, self._scene, values)

    def _repr_png_(self) -> bytes:
        from ._png import encode_png
        return encode_png(self.render(480, 270))

    def __repr__(self) -> str:
        s = self.stats
        return (f"<sdfprune.PrunedGrid {s['grid']}³ ({self.backend}): active "
                f"{s['active_avg']:.3f} ± {s['active_std']:.3f}, "
                f"{s['near_field_cells']} near-field cells, {s['prune_ms']:.1f} ms>")
