"""sdfprune: signed distance fields made of primitives and CSG, evaluated by a C++ engine
that prunes the tree per cell of a hierarchical grid (Lipschitz pruning, Barbier et al. 2025).

    from sdfprune import sphere, box, cylinder, X, Y, Z
    f = sphere(1) & box(1.5)
    c = cylinder(0.5, height=3)
    f -= c.orient(X) | c.orient(Y) | c.orient(Z)
    f.save("out.stl")
    f([[0.6, 0.6, 0.0]])        # array([-0.1], dtype=float32): negative inside

Shapes: sphere, box, cylinder, cone, capsule, torus, primitive(name, **fields), load(path).
Transforms: .translate, .scale, .rotate, .orient; colors: .color(r, g, b) or color=.
Operators: | & - and union / intersection / difference(a, b, k=...) or b.k(...).
Queries: f(points), .discretize(), .mesh(), .render(), .save(path), .prune(grid).
"""
from ._sdfprune import GpuError, __version__
from ._shape import (ORIGIN, SDF3, X, Y, Z, Shape, difference, intersection, load, loads,
                     union)
from ._grid import PrunedGrid
from . import _primitives
from ._primitives import (PRIMITIVES, box, capsule, cone, cylinder, primitive, sphere,
                          torus)

# Every other kind of the engine's primitive table, as a function of its fields.
globals().update({name: getattr(_primitives, name) for name in _primitives.GENERATED})

__all__ = [
    "Shape", "SDF3", "PrunedGrid", "GpuError", "X", "Y", "Z", "ORIGIN",
    "sphere", "box", "cylinder", "cone", "capsule", "torus", "primitive", "PRIMITIVES",
    "union", "intersection", "difference", "load", "loads", "__version__",
] + list(_primitives.GENERATED)
