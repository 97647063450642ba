"""Property tests: every method recovers random noise-free similarities, any rotation."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.orientation import METHODS
from photogeom.rotation import rotation_from_angles

angles = st.tuples(
    st.floats(-math.pi, math.pi), st.floats(-math.pi / 2, math.pi / 2), st.floats(-math.pi, math.pi)
)


def _points(seed: int, n: int, shape: str) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if shape == "planar":  # exactly coplanar (tilted plane)
        p = np.c_[rng.uniform(-10, 10, (n, 2)), np.zeros(n)]
        Q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        return p @ Q.T + rng.normal(scale=30, size=3)
    x = rng.uniform(-10, 10, (n, 3)) + rng.normal(scale=30, size=3)
    if n == 3:  # keep the triangle well shaped
        x[2] = x[0] + np.cross(x[1] - x[0], [0.3, 0.5, 0.8])
    return x


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    ang=angles,
    log_scale=st.floats(-3, 3),
    shift=st.tuples(*[st.floats(-1e5, 1e5)] * 3),
    n=st.integers(3, 9),
    seed=st.integers(0, 2**31),
    shape=st.sampled_from(["general", "planar"]),
    convention=st.sampled_from(["transposed", "direct"]),
)
def test_every_method_recovers_noise_free_similarity(ang, log_scale, shift, n, seed, shape,
                                                      convention):
    R = rotation_from_angles(*ang, convention=convention)
    s = 10.0**log_scale
    t = np.array(shift)
    x = _points(seed, n, shape)
    X = s * x @ R.T + t
    tol_t = 1e-7 * (np.abs(t).max() + s * np.abs(x).max() + 1)
    # the target coordinates carry only spacing(max |X|) absolute precision: over the lever
    # arm of the (scaled) point set that is a rotation / relative scale error of up to
    # delta / lever (e.g. s = 1e-3 with a 6.5e4 m shift and a thin triangle: ~4e-8)
    lever = s * np.linalg.svd(x - x.mean(axis=0), compute_uv=False)[1] / np.sqrt(n)
    rounding = 10 * np.spacing(np.abs(X).max()) / lever
    tol_r, tol_s = 1e-8 + rounding, 1e-9 + rounding
    for m in METHODS:
        fit = pg.absolute_orientation(x, X, m)
        np.testing.assert_allclose(fit.rotation, R, atol=tol_r, err_msg=m)
        assert abs(fit.scale / s - 1) < tol_s, m
        np.testing.assert_allclose(fit.translation, t, atol=tol_t, err_msg=m)
        # apply then inverse is the identity
        np.testing.assert_allclose(fit.transform.inverse().apply(fit.transform.apply(x)), x,
                                   atol=1e-8 * (np.abs(x).max() + 1))
    # the batched solvers too
    for m in ("svd", "quaternion", "dual-quaternion", "closed-form", "gauss-helmert"):
        b = pg.absolute_orientation_batch(x[None], X[None], m)
        assert b.valid[0]
        np.testing.assert_allclose(b.rotation[0], R, atol=tol_r, err_msg=m)
        assert abs(b.scale[0] / s - 1) < tol_s, m


@settings(max_examples=15, deadline=None)
@given(ang=angles, seed=st.integers(0, 2**31))
def test_rigid_recovery_and_angles_round_trip(ang, seed):
    R = rotation_from_angles(*ang)
    x = _points(seed, 6, "general")
    t = np.array([1e3, -2e3, 50.0])
    X = x @ R.T + t
    for m in METHODS:
        fit = pg.absolute_orientation(x, X, m, with_scale=False)
        np.testing.assert_allclose(fit.rotation, R, atol=1e-8, err_msg=m)
        np.testing.assert_allclose(fit.translation, t, atol=1e-6, err_msg=m)
    fit = pg.absolute_orientation(x, X)
    for conv in ("transposed", "direct"):
        back = rotation_from_angles(*fit.angles(conv, "gon"), convention=conv, unit="gon")
        np.testing.assert_allclose(back, R, atol=1e-9)


@settings(max_examples=20, deadline=None)
@given(ang=angles, seed=st.integers(0, 2**31), log_scale=st.floats(-2, 2))
def test_three_point_closed_forms_equal_svd(ang, seed, log_scale):
    """n = 3 with noise: the batched planar SVD, LAPACK SVD and quaternion agree."""
    rng = np.random.default_rng(seed)
    R = rotation_from_angles(*ang)
    x = rng.normal(scale=10, size=(64, 3, 3))
    X = 10**log_scale * x @ R.T + rng.normal(scale=0.5, size=(64, 3, 3))
    a = pg.absolute_orientation_batch(x, X, "svd")
    q = pg.absolute_orientation_batch(x, X, "quaternion")
    ok = a.valid & q.valid
    assert ok.mean() > 0.9
    np.testing.assert_allclose(a.rotation[ok], q.rotation[ok], atol=1e-8)
    np.testing.assert_allclose(a.scale[ok], q.scale[ok], rtol=1e-9)
    for i in np.flatnonzero(ok)[:5]:
        single = pg.absolute_orientation(x[i], X[i], "svd")
        np.testing.assert_allclose(single.rotation, a.rotation[i], atol=1e-8)
