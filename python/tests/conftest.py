"""Shared fixtures: the CLI built beside the package (for comparisons) and the reference
scenes; tests needing either skip with a message when it is absent."""
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _cli():
    env = os.environ.get("SDFPRUNE_CLI")
    for c in ([env] if env else []) + [str(ROOT / "build" / "sdfprune"), shutil.which("sdfprune")]:
        if c and Path(c).is_file() and os.access(c, os.X_OK):
            return c
    return None


@pytest.fixture(scope="session")
def cli():
    c = _cli()
    if not c:
        pytest.skip("the sdfprune CLI is not built (build/sdfprune or $SDFPRUNE_CLI)")

    def run(*args):
        r = subprocess.run([c, *map(str, args)], capture_output=True, text=True)
        if r.returncode != 0:
            raise AssertionError(f"sdfprune {' '.join(map(str, args))}: {r.stderr}")
        return r.stdout
    return run


@pytest.fixture(scope="session")
def scenes():
    d = Path(os.environ.get("SDFPRUNE_SCENES", ROOT.parent / "shared" / "scenes"))
    if not (d / "molecule.json").is_file():
        pytest.skip(f"reference scenes not found in {d} (set SDFPRUNE_SCENES)")
    return d


@pytest.fixture
def example():
    from sdfprune import X, Y, Z, box, cylinder, sphere
    f = sphere(1) & box(1.5)
    c = cylinder(0.5, height=3)
    f -= c.orient(X) | c.orient(Y) | c.orient(Z)
    return f
