"""The Python package's targets (issue 14), run by `make bench` through bench/python.sh:

1. The quick-start scene meshed at fogleman/sdf's default sampling (its mesh() picks the step
   so the grid has about 2^22 samples: here 161^3 corners = 160^3 cubes over the shape's
   bounds): sdfprune's f.mesh() (pruning included) against a plain numpy evaluation of the same
   scene on the same grid followed by skimage's marching cubes (fogleman/sdf's pipeline,
   Debian's python3-skimage). Target: >= x50.
2. f(points) on 10^7 random points in molecule's box (on the pruned 256^3 grid, as the CLI)
   against `sdfprune eval`'s own eval_ms (file I/O and pruning excluded on both sides).
   Target: within 10 %.
3. `import sdfprune` in a fresh interpreter. Target: < 0.3 s.

usage: python bench/python_bench.py --cli build/sdfprune [--scenes ../shared/scenes]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import sdfprune
from sdfprune import X, Y, Z, box, cylinder, sphere


def best(fn, n=3):
    times = []
    for _ in range(n):
        t = time.perf_counter()
        r = fn()
        times.append(time.perf_counter() - t)
    return min(times), r


def example():
    f = sphere(1) & box(1.5)
    c = cylinder(0.5, height=3)
    f -= c.orient(X) | c.orient(Y) | c.orient(Z)
    return f


def numpy_example(p):
    """The same scene written in plain numpy (float32, as the engine)."""
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    s = np.sqrt(x * x + y * y + z * z) - 1
    q = np.abs(p) - 0.75
    b = np.sqrt(np.sum(np.maximum(q, 0) ** 2, axis=-1)) + np.minimum(np.max(q, axis=-1), 0)

    def cyl(radial_a, radial_b, axial):
        dx = np.sqrt(radial_a * radial_a + radial_b * radial_b) - 0.5
        dy = np.abs(axial) - 1.5
        return np.minimum(np.maximum(dx, dy), 0) + np.sqrt(np.maximum(dx, 0) ** 2 + np.maximum(dy, 0) ** 2)

    c = np.minimum(np.minimum(cyl(y, z, x), cyl(x, z, y)), cyl(x, y, z))
    return np.maximum(np.maximum(s, b), -c)


def mesh_target():
    from skimage.measure import marching_cubes
    f = example()
    (lo, hi) = map(np.array, f.bounds)
    step = (np.prod(hi - lo) / 2 ** 22) ** (1 / 3)
    res = int(round((hi - lo).max() / step / 16)) * 16   # 160: 10 -> 40 -> 160 levels
    # The mesher's cube corners: res + 1 per axis over the bounds.
    axes = [np.linspace(lo[i], hi[i], res + 1, dtype=np.float32) for i in range(3)]

    def baseline():
        g = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
        volume = numpy_example(g)
        v, faces, _, _ = marching_cubes(volume, 0, spacing=tuple((hi - lo) / res))
        return len(faces)

    def ours():
        return len(example().mesh(res)[1])  # a fresh shape: pruning included

    t_base, n_base = best(baseline, 2)
    t_ours, n_ours = best(ours, 3)
    f.prune(sdfprune._sdfprune.default_mesh_grid(res), refine=1)  # the grid f.mesh(res) prunes
    t_mesh_only, _ = best(lambda: f.mesh(res), 3)
    ratio = t_base / t_ours
    print(f"mesh, quick-start scene, {res}^3 cubes ({(res + 1) ** 3 / 2 ** 22:.2f} x 2^22 corners):")
    print(f"  numpy evaluation + skimage marching_cubes: {1e3 * t_base:8.1f} ms ({n_base} triangles)")
    print(f"  sdfprune f.mesh(res) (prune + mesh):       {1e3 * t_ours:8.1f} ms ({n_ours} triangles)"
          f"  -> x{ratio:.0f} (target x50: {'met' if ratio >= 50 else 'NOT met'})")
    print(f"  sdfprune mesh on an already pruned grid:   {1e3 * t_mesh_only:8.1f} ms")
    return ratio


def eval_target(cli, scenes):
    mol_path = scenes / "molecule.json"
    if not mol_path.is_file() or not cli:
        print("eval: skipped (needs the CLI and ../shared/scenes/molecule.json)")
        return None
    mol = sdfprune.load(mol_path)
    lo, hi = map(np.array, mol.bounds)
    pts = np.random.default_rng(0).uniform(lo, hi, size=(10_000_000, 3)).astype(np.float32)
    grid = mol.prune(256)
    out = np.empty(len(pts), np.float32)
    t_py, _ = best(lambda: grid(pts, out=out), 3)
    with tempfile.TemporaryDirectory() as d:
        np.save(Path(d) / "p.npy", pts)
        cli_ms = []
        for _ in range(3):
            r = subprocess.run([cli, "eval", str(mol_path), str(Path(d) / "p.npy"), "-o",
                                str(Path(d) / "v.npy"), "--json", "--quiet"],
                               capture_output=True, text=True, check=True)
            cli_ms.append(json.loads(r.stdout.strip().splitlines()[-1])["eval_ms"])
        same = np.array_equal(np.load(Path(d) / "v.npy"), out)
    t_cli = min(cli_ms) / 1e3
    rel = t_py / t_cli - 1
    print("f(points), molecule, 10^7 random float32 points in its box, pruned grid 256^3:")
    print(f"  Python grid(points):        {1e3 * t_py:8.1f} ms")
    print(f"  sdfprune eval (eval_ms):    {1e3 * t_cli:8.1f} ms  -> {100 * rel:+.1f} % "
          f"(target within 10 %: {'met' if rel <= 0.10 else 'NOT met'}); same values: {same}")
    return rel


def import_target():
    code = "import time; t = time.perf_counter(); import sdfprune; print(time.perf_counter() - t)"
    times = [float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                  check=True, cwd=tempfile.gettempdir()).stdout) for _ in range(5)]
    t = min(times)
    print(f"import sdfprune: {1e3 * t:.0f} ms (best of 5; target < 300 ms: "
          f"{'met' if t < 0.3 else 'NOT met'})")
    return t


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cli", default=None)
    ap.add_argument("--scenes", default=os.environ.get(
        "SDFPRUNE_SCENES", str(Path(__file__).resolve().parents[2] / "shared" / "scenes")))
    a = ap.parse_args()
    print(f"sdfprune {sdfprune.__version__}, {os.cpu_count()} cores")
    import_target()
    mesh_target()
    eval_target(a.cli, Path(a.scenes))


if __name__ == "__main__":
    main()
