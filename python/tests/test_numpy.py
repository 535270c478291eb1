"""numpy dtypes and shapes, in-place reads, large arrays, and no crash on odd input."""
import resource
import threading
import time

import numpy as np
import pytest

import sdfprune as sp

f = sp.sphere(1) - sp.box(0.8)
P = np.random.default_rng(3).uniform(-1.5, 1.5, size=(1000, 3))


def test_dtypes_and_layouts():
    want = f(P.astype(np.float32))
    np.testing.assert_array_equal(f(P), want)                       # float64
    np.testing.assert_array_equal(f(P.tolist()), want)              # lists
    np.testing.assert_array_equal(f(np.asfortranarray(P.astype(np.float32))), want)
    big = np.zeros((1000, 6), np.float32)
    big[:, ::2] = P
    np.testing.assert_array_equal(f(big[:, ::2]), want)             # strided view
    assert f(np.zeros((5, 3), np.int32)).shape == (5,)
    assert f([0.0, 0.0, 0.0]).shape == (1,)
    assert f(np.zeros((0, 3), np.float32)).shape == (0,)
    out = np.empty(1000, np.float32)
    assert f(P.astype(np.float32), out=out, exact=False) is out
    np.testing.assert_array_equal(out, f(P, exact=False))
    with pytest.raises(ValueError):
        f(P, out=np.empty(1000), exact=False)          # float64 out: refused, not copied
    with pytest.raises(ValueError):
        f(P, out=np.empty(999, np.float32), exact=False)
    raw = np.zeros(1000 * 12 + 4, np.uint8)
    unaligned = raw[1:1 + 12000].view(np.float32).reshape(1000, 3)
    unaligned[:] = P
    assert not unaligned.flags.aligned
    np.testing.assert_array_equal(f(unaligned, exact=False), f(P, exact=False))


@pytest.mark.parametrize("bad", [np.zeros((4, 2)), np.zeros((2, 3, 3)), np.zeros(5), "abc",
                                 np.array([["a", "b", "c"]]), np.zeros((3, 3), complex),
                                 [[1, 2], [3]], None, np.zeros((0,))])
def test_bad_points_raise(bad):
    with pytest.raises((ValueError, TypeError)):
        f(bad)


def test_nan_and_inf_do_not_crash():
    p = np.array([[np.nan, 0, 0], [np.inf, 0, 0], [-np.inf, np.nan, 1], [0.2, 0, 0]], np.float32)
    for v in (f(p), f(p, exact=True)):
        assert v.shape == (4,) and np.isfinite(v[3])


def test_ten_million_points_in_place():
    n = 10_000_000
    pts = np.random.default_rng(0).uniform(-1.5, 1.5, size=(n, 3)).astype(np.float32)
    out = np.empty(n, np.float32)
    g = f.prune(128)
    g(pts[:10], out=out[:10])
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB, peak so far
    g(pts, out=out)
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    # A copy of the input would be 120 MB; slices of float64 input are converted 1M at a time.
    assert (after - before) * 1024 < 40e6
    np.testing.assert_array_equal(out[:1000], g(pts[:1000]))


def test_gil_released():
    pts = np.random.default_rng(0).uniform(-1.5, 1.5, size=(3_000_000, 3)).astype(np.float32)
    g = f.prune(64)
    ticks = []
    t = threading.Thread(target=lambda: [g(pts, threads=1) for _ in range(3)])
    t.start()
    while t.is_alive():
        ticks.append(1)
        time.sleep(0.001)
    t.join()
    assert len(ticks) > 5


def test_progress_callback():
    seen = []
    sp.sphere(0.7).translate((0.1, 0, 0)).prune(64, progress=seen.append)
    assert seen and seen[-1] == pytest.approx(1.0)
