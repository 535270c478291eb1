"""Primitive shapes. Every primitive comes from the engine's primitive table
(include/sdfprune/primitives.hpp): primitive(name, **fields) builds any kind by its scene-format
fields, and the functions below are its named, documented forms. All are centred on the origin
(or `center`), with their axis along +y like the scene format (use .orient(axis) to turn them).
"""
from __future__ import annotations

import math
from typing import Any, Optional, Sequence, Union

from . import _sdfprune as _core
from ._shape import Shape, _color, _is_number, _vec3

Number = Union[int, float]

# name -> (kind id, summary, [(field, count, required)], bounded), from the engine's table.
PRIMITIVES = {name: (kind, summary, fields, bounded)
              for kind, name, summary, fields, bounded in _core.primitive_table()}


def primitive(name: str, *, center: Optional[Sequence[float]] = None,
              color: Optional[Sequence[float]] = None, **fields: Any) -> Shape:
    """Any primitive of the engine's table by its scene-format name and fields, e.g.
    primitive("box", sides=(1, 2, 1), bevel=(0.1, 0.1, 0.1, 0.1)). sdfprune.PRIMITIVES lists
    the kinds and their fields. Raises ValueError for an unknown kind or field, a missing
    field or an invalid value (the scene loader's checks)."""
    kind, checked = _core.check_primitive(str(name), {k: v for k, v in fields.items()})
    shape = Shape(("prim", kind, checked, None if color is None else _color(color)))
    if center is not None:
        shape = shape.translate(center)
    return shape


def sphere(radius: Number = 1, center: Optional[Sequence[float]] = None, *,
           color: Optional[Sequence[float]] = None) -> Shape:
    """A ball of `radius` about `center` (default: the origin)."""
    return primitive("sphere", radius=radius, center=center, color=color)


def box(size: Union[Number, Sequence[Number]] = 1, center: Optional[Sequence[float]] = None, *,
        bevel: Union[Number, Sequence[Number], None] = None, round_top: Number = 0,
        round_bottom: Number = 0, color: Optional[Sequence[float]] = None) -> Shape:
    """A box of full side lengths `size` (a number for a cube, or (x, y, z)).

    bevel: corner radii of the box's xz outline (one number for all four corners, or 4 for the
    quadrants +x+z, +x−z, −x+z, −x−z); round_top / round_bottom: rounding of the top (+y) and
    bottom (−y) rims (the scene format's round_x / round_y)."""
    sides = (float(size),) * 3 if _is_number(size) else _vec3(size, "size")
    fields: dict = {"sides": sides}
    if bevel is not None:
        fields["bevel"] = (float(bevel),) * 4 if _is_number(bevel) else tuple(bevel)
    if round_top:
        fields["round_x"] = round_top
    if round_bottom:
        fields["round_y"] = round_bottom
    return primitive("box", center=center, color=color, **fields)


def cylinder(radius: Number = 1, height: Number = 2, center: Optional[Sequence[float]] = None,
             *, color: Optional[Sequence[float]] = None) -> Shape:
    """A capped cylinder of `radius` and full `height` along y, centred."""
    return primitive("cylinder", radius=radius, height=height, center=center, color=color)


def cone(radius: Number = 1, height: Number = 2, center: Optional[Sequence[float]] = None, *,
         color: Optional[Sequence[float]] = None) -> Shape:
    """A cone of full `height` along y: base of `radius` at y = −height/2, apex at +height/2."""
    return primitive("cone", radius=radius, height=height, center=center, color=color)


def capsule(radius: Number = 0.5, height: Number = 1, center: Optional[Sequence[float]] = None,
            *, a: Optional[Sequence[float]] = None, b: Optional[Sequence[float]] = None,
            color: Optional[Sequence[float]] = None) -> Shape:
    """All points within `radius` of a segment: of length `height` along y, centred, or from
    point `a` to point `b` when both are given (fogleman/sdf's capsule(a, b, radius))."""
    if (a is None) != (b is None):
        raise ValueError("capsule: give both a and b, or neither")
    if a is None:
        return primitive("capsule", radius=radius, height=height, center=center, color=color)
    pa, pb = _vec3(a, "a"), _vec3(b, "b")
    d = tuple(q - p for p, q in zip(pa, pb))
    length = math.sqrt(sum(v * v for v in d))
    s = primitive("capsule", radius=radius, height=length, color=color)
    if length > 0:
        s = s.orient(d)
    return s.translate(tuple((p + q) / 2 for p, q in zip(pa, pb)))


def torus(major_radius: Number = 1, minor_radius: Number = 0.25,
          center: Optional[Sequence[float]] = None, *,
          color: Optional[Sequence[float]] = None) -> Shape:
    """A torus in the xz plane: a tube of `minor_radius` around a circle of `major_radius`."""
    return primitive("torus", major_radius=major_radius, minor_radius=minor_radius,
                     center=center, color=color)


def _generated(name: str, summary: str, fields: list):
    """A function for a table kind without a hand-written one above: its fields, in the
    table's order, as parameters (optional fields default to the engine's default)."""
    import inspect
    names = [f[0] for f in fields]

    def make(*args: Any, center: Optional[Sequence[float]] = None,
             color: Optional[Sequence[float]] = None, **kw: Any) -> Shape:
        if len(args) > len(names):
            raise TypeError(f"{name}() takes at most {len(names)} positional arguments")
        for n, a in zip(names, args):
            if n in kw:
                raise TypeError(f"{name}() got multiple values for argument '{n}'")
            kw[n] = a
        return primitive(name, center=center, color=color, **kw)

    P = inspect.Parameter
    params = [P(n, P.POSITIONAL_OR_KEYWORD, default=P.empty if req else None)
              for n, _, req in fields]
    params += [P("center", P.KEYWORD_ONLY, default=None), P("color", P.KEYWORD_ONLY, default=None)]
    make.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    make.__name__ = make.__qualname__ = name
    described = ", ".join(f"{n} ({c} numbers)" if c > 1 else n for n, c, _ in fields)
    make.__doc__ = (f"{summary[:1].upper()}{summary[1:]}.\n\nFields (the scene format's, from the "
                    f"engine's primitive table): {described}; center=, color= as for sphere().")
    return make


GENERATED = []
for _name, (_kind, _summary, _fields, _bounded) in PRIMITIVES.items():
    if _name not in globals():
        globals()[_name] = _generated(_name, _summary, _fields)
        GENERATED.append(_name)
