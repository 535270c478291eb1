"""Python against the CLI: the same values (sdfprune eval), statistics (stats --json),
discretization (discretize) and pictures (render) for the same scene; Python-built and
JSON-loaded scenes agree bit for bit."""
import json

import numpy as np
import pytest

import sdfprune as sp

rng = np.random.default_rng(7)


def smooth_scene():
    a = sp.sphere(0.6).translate((-0.3, 0, 0))
    b = sp.box((0.8, 0.5, 0.6)).rotate(0.4, sp.Y).translate((0.35, 0.1, 0))
    c = sp.capsule(0.15, height=1.2).orient(sp.X).color(0.9, 0.2, 0.2)
    d = sp.torus(0.5, 0.1).translate((0, -0.3, 0))
    return sp.difference(sp.union(a, b, k=0.2) | d, c, k=0.05) & sp.sphere(1.1).k(0.1)


@pytest.mark.parametrize("which", ["example", "smooth"])
def test_eval_matches_cli(tmp_path, cli, example, which):
    f = example if which == "example" else smooth_scene()
    scene = tmp_path / "s.json"
    f.save_scene(scene)
    lo, hi = map(np.array, f.bounds)
    pts = rng.uniform(lo - 0.2, hi + 0.2, size=(20000, 3)).astype(np.float32)
    np.save(tmp_path / "p.npy", pts)
    cli("eval", scene, tmp_path / "p.npy", "-o", tmp_path / "pruned.npy", "--quiet")
    cli("eval", scene, tmp_path / "p.npy", "-o", tmp_path / "naive.npy", "--method", "naive",
        "--quiet")
    np.testing.assert_array_equal(f(pts, exact=False), np.load(tmp_path / "pruned.npy"))
    np.testing.assert_array_equal(f(pts, exact=True), np.load(tmp_path / "naive.npy"))
    loaded = sp.load(scene)
    np.testing.assert_array_equal(loaded(pts, exact=False), f(pts, exact=False))
    np.testing.assert_array_equal(loaded(pts, exact=True), f(pts, exact=True))


def test_smooth_operators_formula():
    a, b = sp.sphere(0.5).translate((-0.3, 0, 0)), sp.sphere(0.5).translate((0.3, 0, 0))
    p = rng.uniform(-1, 1, size=(5000, 3)).astype(np.float32)
    da, db = a(p, exact=True).astype(np.float64), b(p, exact=True).astype(np.float64)
    k = 0.3
    phi = lambda x: np.maximum(k - x, 0) ** 2 / (4 * k)
    np.testing.assert_allclose(sp.union(a, b, k=k)(p, exact=True), np.minimum(da, db) - phi(np.abs(da - db)), atol=1e-6)
    np.testing.assert_allclose((a | b.k(k))(p, exact=True), np.minimum(da, db) - phi(np.abs(da - db)), atol=1e-6)
    np.testing.assert_allclose(sp.intersection(a, b, k=k)(p, exact=True), np.maximum(da, db) + phi(np.abs(da - db)), atol=1e-6)
    np.testing.assert_allclose(sp.difference(a, b, k=k)(p, exact=True), np.maximum(da, -db) + phi(np.abs(da + db)), atol=1e-6)
    np.testing.assert_array_equal((a | b)(p, exact=True), np.minimum(da, db).astype(np.float32))
    np.testing.assert_array_equal((a & b)(p, exact=True), np.maximum(da, db).astype(np.float32))
    np.testing.assert_array_equal((a - b)(p, exact=True), np.maximum(da, -db).astype(np.float32))


def test_example_value(example):
    v = example([[0.6, 0.6, 0.0]])
    assert v.shape == (1,) and abs(v[0] + 0.1) < 1e-6


def test_stats_match_cli(tmp_path, cli, example):
    example.save_scene(tmp_path / "s.json")
    want = json.loads(cli("stats", tmp_path / "s.json", "--grid", 64, "--json").splitlines()[-1])
    got = example.prune(64).stats
    for key in ("cells", "near_field_cells", "active_avg", "active_std", "active_max",
                "tape_avg", "tape_max", "levels", "tape_bytes"):
        assert got[key] == pytest.approx(want[key], rel=1e-6), key


def test_gpu_stats_match_cli(tmp_path, cli, example):
    # A Vulkan grid's stats hold the device's figures and each step's work shape under the
    # keys of `stats --backend vulkan --json`, with the same values where the device's
    # scheduling cannot change them (times and measured walks may).
    try:
        got = example.prune(64, backend="vulkan").stats
    except sp.GpuError:
        pytest.skip("this sdfprune has no Vulkan backend or device")
    example.save_scene(tmp_path / "s.json")
    out = cli("stats", tmp_path / "s.json", "--grid", 64, "--backend", "vulkan", "--json")
    want = json.loads(out.splitlines()[-1])
    cli_only = {"scene", "nodes", "bounds", "backend", "far_field", "hierarchy", "farfield_c",
                "refine", "clearance", "peak_rss_bytes", "device_ms", "device_reserve_bytes",
                "device_reserve_ms", "idle_cache_bytes"}
    assert set(want) - cli_only <= set(got), set(want) - cli_only - set(got)
    for key in ("device", "submissions", "subgroups", "subgroup_size", "byte_flags",
                "pool_grows", "slices", "near_field_cells", "tape_max"):
        assert got[key] == want[key], key
    assert got["active_avg"] == pytest.approx(want["active_avg"], rel=1e-6)
    assert got["wall_ms"] >= got["prune_ms"] >= 0
    assert len(got["gpu_steps"]) == len(want["gpu_steps"]) > 0
    for mine, theirs in zip(got["gpu_steps"], want["gpu_steps"]):
        assert set(mine) == set(theirs)
        for key in ("level", "mode", "wide", "wide_runs", "taken", "dispatches", "workgroups", "jobs", "lanes",
                    "lanes_per_tape", "longest_walk_words", "copy_jobs", "scratch_bytes"):
            assert mine[key] == theirs[key], (mine["level"], mine["mode"], key)
        # Walks are measured in every step that has jobs (teams, wide, refinement).
        measured = mine["jobs"] > 0
        assert (mine["walked_words"] > 0) == measured
        assert mine["walked_sum_words"] >= mine["walked_words"]


def test_discretize_matches_cli(tmp_path, cli, example):
    example.save_scene(tmp_path / "s.json")
    cli("discretize", tmp_path / "s.json", "-o", tmp_path / "d.npy", "--res", 48, "--quiet")
    got = example.discretize(48)
    assert got.shape == (48, 48, 48) and got.dtype == np.float32
    np.testing.assert_array_equal(got, np.load(tmp_path / "d.npy"))
    example.save(tmp_path / "py.npy", res=48)
    np.testing.assert_array_equal(np.load(tmp_path / "py.npy"), got)


@pytest.mark.parametrize("shading", ["shaded", "normals"])
def test_render_matches_cli(tmp_path, cli, example, shading):
    example.save_scene(tmp_path / "s.json")
    cli("render", tmp_path / "s.json", "-o", tmp_path / "cli.png", "--width", 96, "--height", 64,
        "--yaw", 40, "--pitch", 20, "--shading", shading, "--quiet")
    img = example.render(96, 64, yaw=40, pitch=20, shading=shading)
    assert img.shape == (64, 96, 3) and img.dtype == np.uint8
    example.save(tmp_path / "py.png", width=96, height=64, yaw=40, pitch=20, shading=shading)
    assert (tmp_path / "py.png").read_bytes() == (tmp_path / "cli.png").read_bytes()
    assert example._repr_png_().startswith(b"\x89PNG")


def test_molecule_load_and_roundtrip(tmp_path, cli, scenes):
    mol = sp.load(scenes / "molecule.json")
    info = mol.info()
    assert info["nodes"] == 2001 and info["depth"] == 1000
    mol.save_scene(tmp_path / "m.json")
    again = sp.load(tmp_path / "m.json")
    lo, hi = map(np.array, mol.bounds)
    pts = rng.uniform(lo, hi, size=(20000, 3)).astype(np.float32)
    np.testing.assert_array_equal(mol(pts, grid=64), again(pts, grid=64))
    # Combined with Python shapes (replayed through the builder): still the same field.
    moved = mol.translate((1, 0, 0))
    np.testing.assert_allclose(moved(pts + np.float32([1, 0, 0]), exact=True)[:2000],
                               mol(pts, exact=True)[:2000], atol=2e-6)
