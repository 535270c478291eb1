"""Outputs by extension, meshes closed and 2-manifold, errors as Python exceptions with the
CLI's messages and nothing written on failure."""
import os

import numpy as np
import pytest

import sdfprune as sp


def test_mesh_closed_manifold(example):
    v, faces = example.mesh(48)
    assert v.dtype == np.float32 and v.shape[1] == 3
    assert faces.dtype == np.uint32 and faces.shape[1] == 3 and len(faces) > 100
    assert faces.max() < len(v)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    directed = {tuple(e) for e in edges.tolist()}
    assert len(directed) == len(edges)                       # each directed edge once
    assert all((b, a) in directed for a, b in directed)      # and its twin: closed, 2-manifold
    a, b, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    volume = np.einsum("ij,ij->i", a.astype(np.float64), np.cross(b, c)).sum() / 6
    assert volume > 0                                        # outward orientation


@pytest.mark.parametrize("ext", [".stl", ".ply", ".obj", ".npy", ".vdb", ".png"])
def test_save_by_extension(tmp_path, example, ext):
    path = tmp_path / f"out{ext}"
    example.save(path, res=32, width=64, height=48)
    assert path.stat().st_size > 0
    assert sorted(os.listdir(tmp_path)) == [path.name]        # no temporary left behind


def test_bad_outputs_write_nothing(tmp_path, example):
    with pytest.raises(OSError, match="unknown output extension"):
        example.save(tmp_path / "out.xyz")
    with pytest.raises(OSError):
        example.save(tmp_path / "missing" / "out.stl")
    with pytest.raises(OSError):
        example.save_scene(tmp_path / "missing" / "s.json")
    with pytest.raises(ValueError):
        example.save(tmp_path / "out.stl", res=0)
    assert os.listdir(tmp_path) == []


def test_bad_scenes(tmp_path):
    with pytest.raises(OSError):
        sp.load(tmp_path / "nope.json")
    (tmp_path / "bad.json").write_text('{"aabb_min": [-1, -1, -1], "aabb_max": [1, 1, 1], '
                                       '"nodeType": "primitive", "primitiveType": "sphere", '
                                       '"radius": -1, "matrix": [1,0,0,0,0,1,0,0,0,0,1,0]}')
    with pytest.raises(ValueError, match="radius must be > 0"):
        sp.load(tmp_path / "bad.json")
    with pytest.raises(ValueError):
        sp.loads("{not json")


def test_bad_arguments():
    with pytest.raises(ValueError, match="radius must be > 0"):
        sp.sphere(-1)
    with pytest.raises(ValueError):
        sp.sphere(float("nan"))
    with pytest.raises(ValueError):
        sp.box((1, 2))
    with pytest.raises(ValueError, match="unknown primitive"):
        sp.primitive("blob", radius=1)
    with pytest.raises(ValueError, match="unknown field"):
        sp.primitive("sphere", radius=1, colour=2)
    with pytest.raises(ValueError):
        sp.union(sp.sphere(1), sp.sphere(1), k=-1)
    with pytest.raises(ValueError):
        sp.sphere(1).scale(0)
    with pytest.raises(ValueError):
        sp.sphere(1).rotate(1, (0, 0, 0))
    with pytest.raises(ValueError):
        sp.sphere(1).color(2, 0, 0)
    with pytest.raises(TypeError):
        sp.sphere(1) | 3
    f = sp.sphere(1)
    for bad in (dict(grid=0), dict(grid=5000), dict(refine=0), dict(backend="cuda"),
                dict(threads=-1), dict(far_field_c=0.5)):
        with pytest.raises(ValueError):
            f.prune(**bad)
    with pytest.raises(ValueError):
        f.render(0, 10)
    with pytest.raises(ValueError):
        f.render(10, 10, shading="toon")
    with pytest.raises(ValueError):
        f.discretize(0)


def test_vulkan_backend_or_clear_error():
    f = sp.sphere(1)
    try:
        g = f.prune(32, backend="vulkan")
    except sp.GpuError as e:
        assert isinstance(e, RuntimeError) and str(e)
        return
    d = g.discretize()
    np.testing.assert_array_equal(d, f.prune(32).discretize())


def test_vulkan_grids_share_one_device_across_threads():
    # The GPU grids alive share one device; threads take turns on it (its lock), and a grid
    # outlives the others it was made beside.
    import gc
    import threading
    try:
        sp.sphere(1).prune(16, backend="vulkan")
    except sp.GpuError:
        pytest.skip("this sdfprune has no Vulkan backend or device")
    shapes = [sp.sphere(1),
              sp.union(sp.sphere(0.6).translate([0.4, 0, 0]), sp.sphere(0.5), k=0.2),
              sp.sphere(0.8) - sp.sphere(0.5).translate([0.5, 0.2, 0])]
    made = {}
    errors = []

    def work(i):
        try:
            g = shapes[i].prune(32, backend="vulkan")
            made[i] = (g, g.discretize(32), g.render(64, 48))
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(len(shapes))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert len({made[i][0].stats["device"] for i in made}) == 1
    for i, f in enumerate(shapes):
        np.testing.assert_array_equal(made[i][1], f.prune(32).discretize(32))
    keep = made.pop(1)
    made.clear()
    gc.collect()
    np.testing.assert_array_equal(keep[0].discretize(32), keep[1])


def test_pruned_grid_reuse(example):
    g = example.prune(64)
    assert g is example.prune(64)
    assert g.stats["grid"] == 64 and g.resolution == 64
    v, faces = g.mesh()
    assert len(faces) > 0
    assert g.discretize().shape == (64, 64, 64)
    p = np.array([[0.6, 0.6, 0], [0.3, 0.2, 0.75]], np.float32)
    want = g(p)
    del example
    import gc
    gc.collect()
    np.testing.assert_array_equal(g(p), want)   # the grid keeps its scene alive
