"""Loads the molecule (2001 nodes) from the reference scenes, prunes it once, and saves a mesh
and a picture from the same pruned grid.

    python examples/molecule.py [SCENE.json] [OUT_PREFIX]
"""
import sys
import time
from pathlib import Path

import sdfprune

root = Path(__file__).resolve().parents[2]  # the repository (examples/ -> python/examples/)
scene = sys.argv[1] if len(sys.argv) > 1 else root.parent / "shared" / "scenes" / "molecule.json"
prefix = sys.argv[2] if len(sys.argv) > 2 else "molecule"

mol = sdfprune.load(scene)
t = time.perf_counter()
grid = mol.prune(256, progress=True)
print(f"pruned in {time.perf_counter() - t:.2f} s: {grid.stats['active_avg']:.3f} active "
      f"primitives per cell on average (of {mol.info()['primitives']})")
grid.save(f"{prefix}.ply")
grid.save(f"{prefix}.png", width=960, height=540)
print(f"wrote {prefix}.ply and {prefix}.png")
