"""Each primitive against its analytic distance, exactly and through the pruned grid."""
import numpy as np
import pytest

import sdfprune as sp

rng = np.random.default_rng(1)
P = rng.uniform(-2, 2, size=(4000, 3)).astype(np.float32)


def length(v, axis=-1):
    return np.sqrt(np.sum(v * v, axis=axis))


def sd_box(p, half):
    q = np.abs(p) - half
    return length(np.maximum(q, 0)) + np.minimum(np.max(q, axis=-1), 0)


def sd_cylinder(p, r, h):
    d = np.stack([length(p[:, [0, 2]]) - r, np.abs(p[:, 1]) - h / 2], axis=-1)
    return np.minimum(np.max(d, axis=-1), 0) + length(np.maximum(d, 0))


def sd_cone(p, r, height):
    # iq's exact capped cone, r1 = r at y = -h, r2 = 0 at y = +h.
    h, r1, r2 = height / 2, r, 0.0
    q = np.stack([length(p[:, [0, 2]]), p[:, 1]], axis=-1)
    k1 = np.array([r2, h])
    k2 = np.array([r2 - r1, 2 * h])
    ca = np.stack([q[:, 0] - np.minimum(q[:, 0], np.where(q[:, 1] < 0, r1, r2)),
                   np.abs(q[:, 1]) - h], axis=-1)
    t = np.clip(((k1 - q) @ k2) / (k2 @ k2), 0, 1)
    cb = q - k1 + k2 * t[:, None]
    s = np.where((cb[:, 0] < 0) & (ca[:, 1] < 0), -1.0, 1.0)
    return s * np.sqrt(np.minimum(np.sum(ca * ca, -1), np.sum(cb * cb, -1)))


CASES = [
    (lambda: sp.sphere(0.8), lambda p: length(p) - 0.8),
    (lambda: sp.sphere(0.5, center=(0.2, -0.1, 0.3)),
     lambda p: length(p - np.array([0.2, -0.1, 0.3])) - 0.5),
    (lambda: sp.box((1.0, 0.6, 1.4)), lambda p: sd_box(p, np.array([0.5, 0.3, 0.7]))),
    (lambda: sp.box(1.2), lambda p: sd_box(p, np.array([0.6, 0.6, 0.6]))),
    (lambda: sp.cylinder(0.5, height=1.5), lambda p: sd_cylinder(p, 0.5, 1.5)),
    (lambda: sp.cone(0.6, height=1.2), lambda p: sd_cone(p, 0.6, 1.2)),
    (lambda: sp.capsule(0.3, height=1.0),
     lambda p: length(p - np.stack([0 * p[:, 0], np.clip(p[:, 1], -0.5, 0.5), 0 * p[:, 0]], -1)) - 0.3),
    (lambda: sp.torus(0.8, 0.2),
     lambda p: length(np.stack([length(p[:, [0, 2]]) - 0.8, p[:, 1]], -1)) - 0.2),
    # The scene format's convention: the field of a scaled shape is the unscaled field at the
    # mapped point (a uniform scale s divides values by s; the zero set is exact).
    (lambda: sp.sphere(0.5).scale(2), lambda p: length(p) / 2 - 0.5),
    (lambda: sp.cylinder(0.4, height=1.0).orient(sp.X),
     lambda p: sd_cylinder(p[:, [1, 0, 2]], 0.4, 1.0)),
]


@pytest.mark.parametrize("make,analytic", CASES)
def test_primitive_matches_analytic(make, analytic):
    f = make()
    want = analytic(P.astype(np.float64))
    exact = f(P, exact=True)
    assert exact.dtype == np.float32 and exact.shape == (len(P),)
    np.testing.assert_allclose(exact, want, atol=2e-5)
    # Through the pruned grid: exact near the surface, a same-sign lower bound elsewhere.
    pruned = f(P, exact=False)
    assert np.all(np.sign(pruned) == np.sign(exact))
    assert np.all(np.abs(pruned) <= np.abs(exact) + 1e-6)
    near = np.abs(exact) < 0.002
    np.testing.assert_array_equal(pruned[near], exact[near])


def test_box_options_and_generic_primitive():
    a = sp.box((1, 1, 1), bevel=0.1, round_top=0.05)
    b = sp.primitive("box", sides=(1, 1, 1), bevel=(0.1, 0.1, 0.1, 0.1), round_x=0.05)
    np.testing.assert_array_equal(a(P, exact=True), b(P, exact=True))
    assert "sphere" in sp.PRIMITIVES and "torus" in sp.PRIMITIVES


def test_capsule_endpoints():
    f = sp.capsule(0.2, a=(0, 0, 0), b=(1, 0, 0))
    p = np.array([[0.5, 0.5, 0], [-0.5, 0, 0], [1.3, 0, 0]], np.float32)
    np.testing.assert_allclose(f(p, exact=True), [0.3, 0.3, 0.1], atol=1e-6)


def test_docstrings():
    assert "radius" in sp.sphere.__doc__
    assert sp.box.__doc__ and sp.Shape.translate.__doc__ and sp.Shape.__call__.__doc__


def test_every_table_kind_has_a_function():
    import inspect
    for name, (kind, summary, fields, bounded) in sp.PRIMITIVES.items():
        fn = getattr(sp, name)
        assert fn.__doc__
        params = inspect.signature(fn).parameters
        assert all(f[0] in params or name in ("box",) for f in fields), name


def test_plane_half_space_and_bounds():
    if "plane" not in sp.PRIMITIVES:
        pytest.skip("this engine has no plane primitive")
    half = sp.plane((0, 2, 0), 0.2)                     # y <= 0.2
    with pytest.raises(ValueError):
        half.bounds                                     # unbounded: bounds must be given
    f = half.bounded(((-1, -1, -1), (1, 1, 1)))
    np.testing.assert_allclose(f(P, exact=True), P[:, 1] - 0.2, atol=1e-6)
    cut = sp.sphere(1) & sp.plane(normal=(0, 1, 0))
    np.testing.assert_allclose(cut(P, exact=True),
                               np.maximum(length(P.astype(np.float64)) - 1, P[:, 1]), atol=2e-6)
