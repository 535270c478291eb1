#!/usr/bin/env python3
"""Writes the fuzz targets' seed corpora under fuzz/corpus/<target>/ from the reference scene
format's features (../shared/scenes/README.md): every primitive type with every field, every
blendMode (hard and smooth), nesting (left-deep, right-deep, balanced), non-trivial matrices,
AABBs, ignored fields; and small .npy files (every format version, shapes of rank 0 to 3, the
header variants numpy writes, and refused dtypes). Deterministic; run from the repository root:
    python3 fuzz/make_corpus.py
The reference scenes (../shared/scenes: test.json, molecule.json, trees.json) are external data
and are never copied: fuzz/run.sh reads ../shared/scenes as a further seed corpus where it is."""
import json
import math
import os
import struct
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus")
I = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]


def mat(tx=0.0, ty=0.0, tz=0.0, rot=0.0, scale=1.0, shear=0.0):
    c, s = math.cos(rot) * scale, math.sin(rot) * scale
    return [c, 0, s, tx, shear, scale, 0, ty, -s, 0, c, tz]


def prim(kind, m=None, **fields):
    n = {"nodeType": "primitive", "matrix": m or I, "primitiveType": kind}
    n.update(fields)
    return n


def op(mode, k, left, right, m=None):
    return {"nodeType": "binaryOperator", "blendMode": mode, "blendRadius": k,
            "matrix": m or I, "leftChild": left, "rightChild": right}


def scene(root, lo=-2.0, hi=2.0):
    s = {"aabb_min": [lo] * 3, "aabb_max": [hi] * 3}
    s.update(root)
    return s


PRIMS = {
    "sphere": prim("sphere", mat(0.1), radius=0.8, round_x=0, round_y=0, color=[1, 0, 0]),
    "box": prim("box", mat(0, 0.2, 0, 0.3), sides=[1, 0.6, 1.4], bevel=[0.1, 0.2, 0, 0.3],
                round_x=0.05, round_y=0.1, color=[0.2, 0.4, 0.6]),
    "cylinder": prim("cylinder", mat(0, 0, 0.3), height=1.5, radius=0.4, round_x=0, round_y=0,
                     color=[0, 1, 0]),
    "cone": prim("cone", mat(0.2, 0, 0, 0.5), height=1.2, radius=0.6, color=[0, 0, 1]),
    "capsule": prim("capsule", mat(0, -0.1, 0), height=0.8, radius=0.3, color=[1, 1, 0]),
    "torus": prim("torus", mat(0, 0, 0, 0.7), major_radius=0.7, minor_radius=0.2,
                  color=[0.5, 0.5, 0.5]),
}


def scenes():
    out = {}
    for name, p in PRIMS.items():
        out["prim_" + name] = scene(p)
    kinds = list(PRIMS)
    for mode in ("union", "inter", "sub"):
        for k in (0, 0.15):
            out[f"op_{mode}_{k}"] = scene(op(mode, k, PRIMS["sphere"], PRIMS["box"], mat(0.1, 0.1)))
    # Every primitive under every operator, balanced.
    leaves = [PRIMS[k] for k in kinds]
    modes = ["union", "sub", "inter", "union", "union"]
    i = 0
    while len(leaves) > 1:
        nxt = []
        for a in range(0, len(leaves) - 1, 2):
            nxt.append(op(modes[i % len(modes)], 0.05 * (i % 3), leaves[a], leaves[a + 1]))
            i += 1
        if len(leaves) % 2:
            nxt.append(leaves[-1])
        leaves = nxt
    out["balanced_all"] = scene(leaves[0], -3, 3)
    # Left- and right-deep chains.
    for side in ("left", "right"):
        t = prim("sphere", mat(-1), radius=0.3)
        for j in range(24):
            p = prim(kinds[j % len(kinds)], mat(-1 + j * 0.09, 0.1 * (j % 3)),
                     **{k: v for k, v in PRIMS[kinds[j % len(kinds)]].items()
                        if k not in ("nodeType", "matrix", "primitiveType")})
            mode = ["union", "sub", "inter"][j % 3] if j % 4 == 3 else "union"
            t = op(mode, 0.02 * (j % 2), t, p) if side == "left" else op(mode, 0.02 * (j % 2), p, t)
        out[f"chain_{side}"] = scene(t)
    # Scaled, sheared and translated matrices composed through operators.
    out["matrices"] = scene(op("union", 0.1,
                               prim("sphere", mat(0.3, 0, 0, 0.2, 2.0), radius=0.5),
                               prim("box", mat(0, 0, 0, 0, 0.7, 0.4), sides=[1, 1, 1]),
                               mat(0, 0, 0, 0.4, 1.3)), -4, 4)
    out["aabb_offset"] = scene(PRIMS["torus"], -0.5, 1.5)
    out["aabb_flat"] = {"aabb_min": [-2, -0.01, -2], "aabb_max": [2, 0.01, 2], **PRIMS["box"]}
    out["ignored_fields"] = scene({**PRIMS["sphere"], "name": "ball", "extra": {"a": [1, {"b": None}]},
                                   "flag": True, "big": 1e300})
    return out


NPY_MAGIC = b"\x93NUMPY"


def npy(shape, values, descr="<f4", fortran=False, version=1, quote="'", long_suffix=""):
    dims = ", ".join(f"{d}{long_suffix}" for d in shape) + ("," if len(shape) == 1 else "")
    q = quote
    header = f"{{{q}descr{q}: {q}{descr}{q}, {q}fortran_order{q}: {fortran}, {q}shape{q}: ({dims}), }}"
    prefix = 10 if version == 1 else 12
    total = (prefix + len(header) + 1 + 63) // 64 * 64
    header = header + " " * (total - prefix - len(header) - 1) + "\n"
    size = struct.pack("<H", len(header)) if version == 1 else struct.pack("<I", len(header))
    fmt = {"<f4": "<f", "<f8": "<d", ">f4": ">f", "<i4": "<i"}[descr]
    data = b"".join(struct.pack(fmt, v) for v in values)
    return NPY_MAGIC + bytes([version, 0]) + size + header.encode("latin-1") + data


def npys():
    out = {}
    for version in (1, 2, 3):
        out[f"v{version}_2x3"] = npy((2, 3), [0.5 * i for i in range(6)], version=version)
    out["scalar"] = npy((), [3.25])
    out["empty"] = npy((0,), [])
    out["empty_2d"] = npy((4, 0), [])
    out["points_4x3"] = npy((4, 3), [0.1 * i - 0.5 for i in range(12)])
    out["cube_2x2x2"] = npy((2, 2, 2), [float(i) for i in range(8)])
    out["fortran_1d"] = npy((5,), [1, 2, 3, 4, 5], fortran=True)
    out["fortran_2d"] = npy((2, 2), [1, 2, 3, 4], fortran=True)
    out["double_quotes"] = npy((3,), [1, 2, 3], quote='"')
    out["py2_long"] = npy((2, 3), [0] * 6, long_suffix="L")
    out["special_values"] = npy((4,), [float("inf"), float("-inf"), float("nan"), -0.0])
    out["dtype_f8"] = npy((2,), [1, 2], descr="<f8")
    out["dtype_be_f4"] = npy((2,), [1, 2], descr=">f4")
    out["dtype_i4"] = npy((2,), [1, 2], descr="<i4")
    out["truncated"] = npy((4, 3), [0.0] * 12)[:-5]
    return out


# Option bytes of prune_eval (fuzz_entry.hpp): resolution, factor, flags, refine, C, seed x3.
OPTIONS = [
    bytes([15, 2, 0, 2, 64, 1, 2, 3]),   # 16³, factor 4, defaults, refine 3, C 2
    bytes([7, 0, 4, 0, 64, 4, 5, 6]),    # 8³, factor 2, Lipschitz bounds, refine 1
    bytes([11, 1, 2, 1, 0, 7, 8, 9]),    # 12³, factor 3, no hierarchy, refine 2, C 1
    bytes([3, 2, 1, 2, 128, 0, 0, 1]),   # 4³, no far field, C 3
    bytes([9, 2, 8, 2, 32, 9, 9, 9]),    # 10³, coarse tapes, C 1.5
]


def write(target, name, data):
    d = os.path.join(ROOT, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def main():
    sc = scenes()
    for i, (name, s) in enumerate(sorted(sc.items())):
        text = s if isinstance(s, str) else json.dumps(s, separators=(",", ":"))
        write("scene_loader", name + ".json", text.encode())
        write("prune_eval", name + ".bin", OPTIONS[i % len(OPTIONS)] + text.encode())
    for name, data in sorted(npys().items()):
        write("npy_reader", name + ".npy", data)
    return 0


if __name__ == "__main__":
    sys.exit(main())
