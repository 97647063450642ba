"""Absolute orientation: methods against each other (random problems), statistics, options."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import photogeom as pg
from photogeom import datasets
from photogeom.orientation import METHODS
from photogeom.orientation.absolute_direct import (
    PairMoments,
    batch_moments,
    large_moments,
    solve_dual_quaternion,
    solve_svd,
)
from photogeom.orientation.absolute_stats import opk_transposed
from photogeom.rotation import angles_from_rotation
from photogeom.transforms import Similarity3D


def _problem(seed, n=15, noise=0.01, scale=None):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    s = rng.uniform(0.2, 5.0) if scale is None else scale
    t = rng.normal(scale=300.0, size=3)
    x = rng.normal(scale=20.0, size=(n, 3)) + rng.normal(scale=50.0, size=3)
    X = s * x @ R.T + t + rng.normal(scale=noise, size=(n, 3))
    return x, X, (s, R, t)


@pytest.mark.parametrize("seed", range(6))
def test_lsq_methods_agree_on_random_problems(seed):
    x, X, _ = _problem(seed)
    w = np.random.default_rng(seed).uniform(0.3, 3.0, x.shape[0])
    for weights in (None, w):
        ref = pg.absolute_orientation(x, X, "gauss-markov", weights=weights)
        for m in ("svd", "quaternion", "dual-quaternion"):
            fit = pg.absolute_orientation(x, X, m, weights=weights)
            assert fit.scale == pytest.approx(ref.scale, rel=1e-9)
            np.testing.assert_allclose(fit.rotation, ref.rotation, atol=1e-9)
            np.testing.assert_allclose(fit.translation, ref.translation, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_direct_statistics_equal_gauss_markov_statistics(seed):
    """The closed-form 7x7 normal matrix equals the engine's full-Jacobian one."""
    x, X, _ = _problem(seed)
    w = np.random.default_rng(seed + 10).uniform(0.3, 3.0, x.shape[0])
    for weights in (None, w):
        gm = pg.absolute_orientation(x, X, "gauss-markov", weights=weights)
        for m in ("svd", "quaternion", "dual-quaternion"):
            fit = pg.absolute_orientation(x, X, m, weights=weights)
            np.testing.assert_allclose(fit.cofactor, gm.cofactor, rtol=1e-7, atol=1e-14)
            assert fit.sigma0 == pytest.approx(gm.sigma0, rel=1e-9)
            np.testing.assert_allclose(fit.redundancy_numbers, gm.redundancy_numbers, atol=1e-10)
            np.testing.assert_allclose(
                fit.normalized_residuals, gm.normalized_residuals, rtol=1e-7, atol=1e-9
            )


def test_rigid_model():
    x, X, (_, R, _) = _problem(3, scale=1.0, noise=0.0)
    for m in METHODS:
        fit = pg.absolute_orientation(x, X, m, with_scale=False)
        assert fit.scale == 1.0
        assert "scale" not in fit.std_errors
        assert len(fit.parameters) == 6
        np.testing.assert_allclose(fit.rotation, R, atol=1e-9)
    # noisy: every least-squares method gives the same rigid fit and statistics
    x, X, _ = _problem(4, scale=1.0)
    ref = pg.absolute_orientation(x, X, "gauss-markov", with_scale=False)
    assert ref.redundancy == 3 * x.shape[0] - 6
    for m in ("svd", "quaternion", "dual-quaternion", "gauss-helmert"):
        fit = pg.absolute_orientation(x, X, m, with_scale=False)
        np.testing.assert_allclose(fit.parameters, ref.parameters, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(
        pg.absolute_orientation(x, X, "svd", with_scale=False).cofactor, ref.cofactor, rtol=1e-7
    )


def test_gauss_helmert_direct_equals_iterative_and_prescaling():
    x, X = datasets.point_pairs("lidar_wang2014")[1:]
    direct = pg.absolute_orientation(x, X, "gauss-helmert")
    it = pg.absolute_orientation(x, X, "gauss-helmert", iterate=True)
    assert it.iterations >= 1 and it.converged
    np.testing.assert_allclose(direct.parameters, it.parameters, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(direct.cofactor, it.cofactor, rtol=1e-8, atol=1e-16)
    assert direct.sigma0 == pytest.approx(it.sigma0, rel=1e-10)
    np.testing.assert_allclose(direct.corrected_source, it.corrected_source, atol=1e-10)
    np.testing.assert_allclose(direct.corrected_target, it.corrected_target, atol=1e-10)
    np.testing.assert_allclose(direct.redundancy_numbers, it.redundancy_numbers, atol=1e-10)
    # one sigma per system: prescaling reproduces the iterative weighted adjustment
    kw = dict(sigma_source=0.004, sigma_target=0.03)
    pre = pg.absolute_orientation(x, X, "gauss-helmert", **kw)
    it2 = pg.absolute_orientation(x, X, "gauss-helmert", iterate=True, **kw)
    np.testing.assert_allclose(pre.parameters, it2.parameters, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(pre.cofactor, it2.cofactor, rtol=1e-8, atol=1e-16)
    # ... and per-point / block covariances holding the same numbers give the same estimate
    n = x.shape[0]
    blk = pg.absolute_orientation(
        x, X, "gauss-helmert",
        covariance_source=np.tile(np.eye(3) * 0.004**2, (n, 1, 1)),
        covariance_target=np.tile(np.eye(3) * 0.03**2, (n, 1, 1)),
    )
    np.testing.assert_allclose(blk.parameters, pre.parameters, rtol=1e-10, atol=1e-10)
    full = pg.absolute_orientation(
        x, X, "gauss-helmert", covariance_source=np.eye(3 * n) * 0.004**2,
        sigma_target=np.full((n, 3), 0.03),
    )
    np.testing.assert_allclose(full.parameters, pre.parameters, rtol=1e-10, atol=1e-10)
    # the corrected coordinates satisfy the model exactly
    np.testing.assert_allclose(
        it2.transform.apply(it2.corrected_source), it2.corrected_target, atol=1e-9
    )


def test_gauss_helmert_per_point_sigmas_differ_from_equal_weights():
    x, X, _ = _problem(5, noise=0.05)
    n = x.shape[0]
    sig = np.linspace(0.01, 0.2, n)
    fit = pg.absolute_orientation(x, X, "gauss-helmert", sigma_source=sig, sigma_target=sig)
    eq = pg.absolute_orientation(x, X, "gauss-helmert")
    assert fit.iterations >= 1 and "iterative" in " ".join(fit.notes)
    assert not np.allclose(fit.parameters, eq.parameters, rtol=1e-9)
    assert fit.extras["source_residuals"].shape == (n, 3)


def test_gauss_markov_from_any_initial_values():
    x, X, (s, R, t) = _problem(7)
    ref = pg.absolute_orientation(x, X, "svd")
    start = Similarity3D(s * 1.3, Rotation.from_rotvec([0.4, -0.3, 0.5]).as_matrix() @ R, t + 5)
    for init in ("closed-form", "quaternion", "gauss-helmert", start,
                 np.r_[ref.parameters[:4], np.array(ref.parameters[4:]) + 0.2]):
        fit = pg.absolute_orientation(x, X, "gauss-markov", initial=init)
        assert fit.converged
        np.testing.assert_allclose(fit.rotation, ref.rotation, atol=1e-9)
        assert fit.scale == pytest.approx(ref.scale, rel=1e-9)


def test_gauss_markov_per_coordinate_weights_and_covariance():
    x, X, _ = _problem(8)
    n = x.shape[0]
    rng = np.random.default_rng(8)
    sig = rng.uniform(0.005, 0.05, (n, 3))
    a = pg.absolute_orientation(x, X, "gauss-markov", sigma_target=sig)
    b = pg.absolute_orientation(x, X, "gauss-markov", weights=1 / sig**2)
    c = pg.absolute_orientation(
        x, X, "gauss-markov", covariance_target=np.einsum("ni,ij->nij", sig**2, np.eye(3))
    )
    d = pg.absolute_orientation(x, X, "gauss-markov", covariance=np.diag(sig.reshape(-1) ** 2))
    for f in (b, c, d):
        np.testing.assert_allclose(f.parameters, a.parameters, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(f.cofactor, a.cofactor, rtol=1e-8)


def test_scale_methods():
    x, X, _ = _problem(9, noise=0.5)
    ls = pg.absolute_orientation(x, X, "quaternion")
    sym = pg.absolute_orientation(x, X, "quaternion", scale_method="symmetric")
    xr, Xr = x - x.mean(0), X - X.mean(0)
    assert sym.scale == pytest.approx(np.sqrt(np.sum(Xr**2) / np.sum(xr**2)), rel=1e-12)
    assert ls.scale == pytest.approx(pg.absolute_orientation(x, X, "svd").scale, rel=1e-12)
    assert sym.scale != pytest.approx(ls.scale, rel=1e-9)
    np.testing.assert_allclose(sym.rotation, ls.rotation, atol=1e-12)


def test_dual_quaternion_with_off_centre_reference():
    """The dual-quaternion route does real work when the moments are not centred."""
    x, X, _ = _problem(12)
    m = batch_moments(x[None], X[None])
    ref = solve_svd(m)
    # the same data, moments about the first point instead of the centroid
    u, U = x - x[0], X - X[0]
    from photogeom.orientation.absolute_direct import Moments

    m0 = Moments(
        np.array([float(len(x))]), x[:1], X[:1], u.sum(0)[None], U.sum(0)[None],
        (u.T @ U)[None], np.array([np.sum(u * u)]), np.array([np.sum(U * U)]),
    )
    dq = solve_dual_quaternion(m0)
    np.testing.assert_allclose(dq.rotation, ref.rotation, atol=1e-10)
    np.testing.assert_allclose(dq.scale, ref.scale, rtol=1e-10)
    np.testing.assert_allclose(dq.translation, ref.translation, rtol=1e-10, atol=1e-8)


def test_one_pass_moments_equal_exact_moments():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(70001, 3)) * 5 + 20
    X = rng.normal(size=(70001, 3)) * 3 - 7
    w = rng.uniform(0.5, 2, 70001)
    for ww in (None, w):
        a = PairMoments.from_moments(large_moments(x, X, ww))
        b = PairMoments.of(x, X, ww)
        np.testing.assert_allclose(a.H, b.H, rtol=1e-10, atol=1e-10 * np.abs(b.H).max())
        assert a.a == pytest.approx(b.a, rel=1e-11)
        assert a.b == pytest.approx(b.b, rel=1e-11)
        np.testing.assert_allclose(a.source_centroid, b.source_centroid, rtol=1e-12)
    fast = pg.absolute_orientation(x, X, statistics=False)
    full = pg.absolute_orientation(x, X)
    assert fast.residuals.shape == (0, 3) and np.isnan(fast.sigma0)
    np.testing.assert_allclose(fast.parameters, full.parameters, rtol=1e-9, atol=1e-12)


def test_fast_angle_extraction_matches_library():
    for seed in range(20):
        R = Rotation.random(random_state=seed).as_matrix()
        w, p, k, gimbal = opk_transposed(R)
        assert not gimbal
        np.testing.assert_allclose((w, p, k), angles_from_rotation(R, "transposed"), atol=1e-15)


def test_trusted_similarity_equals_checked_construction():
    from photogeom.orientation.absolute import _similarity

    R = Rotation.random(random_state=1).as_matrix()
    a = _similarity(2.5, R, [1.0, 2.0, 3.0])
    b = Similarity3D(2.5, R, [1.0, 2.0, 3.0])
    assert vars(a).keys() == vars(b).keys()
    for key in vars(b):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    assert not a.rotation.flags.writeable
    assert a.to_dict() == b.to_dict()


def test_fit_conventions_and_units():
    x, X = datasets.point_pairs("lidar_wang2014")[1:]
    fit = pg.absolute_orientation(x, X, "svd", unit="m", ids=[f"P{i}" for i in range(18)])
    assert fit.ids[0] == "P0"
    w, p, k = fit.angles("transposed", "rad")
    assert (w, p, k) == pytest.approx((fit.params["omega"], fit.params["phi"], fit.params["kappa"]))
    wd = fit.angles("direct", "deg")
    np.testing.assert_allclose(
        pg.rotation_from_angles(*wd, convention="direct", unit="deg"), fit.rotation, atol=1e-14
    )
    gon = fit.angles("transposed", "gon")
    np.testing.assert_allclose(np.array(gon) * 0.9, np.degrees([w, p, k]), atol=1e-12)
    text = fit.summary("gon")
    assert "gon" in text and "computed - observed" in text
    assert fit.elapsed > 0
    sn = fit.snooping()
    assert sn.statistic.shape == (54,)


def test_gimbal_lock_attitude():
    """phi = 90 deg: the rotation is fine, omega and kappa are not separable (std NaN)."""
    from photogeom.rotation import rotation_from_angles

    R = rotation_from_angles(0.4, np.pi / 2, -1.1)
    rng = np.random.default_rng(2)
    x = rng.uniform(-10, 10, (8, 3))
    X = 1.2 * x @ R.T + np.array([5.0, 6.0, 7.0])  # noise-free: phi is exactly 90 deg
    ref = pg.absolute_orientation(x, X, "svd")
    for m in METHODS:
        fit = pg.absolute_orientation(x, X, m)
        np.testing.assert_allclose(fit.rotation, R, atol=1e-9)
        assert any("gimbal lock" in n for n in fit.notes), m
        assert fit.params["omega"] == 0.0
        sd = fit.std_errors_prior  # a priori: the data are noise-free
        assert np.isnan(sd["omega"]) and np.isnan(sd["kappa"]), m
        assert np.isfinite(sd["tx"]) and np.isfinite(sd["scale"]), m
        if m in ("quaternion", "dual-quaternion", "gauss-markov"):
            assert sd["tx"] == pytest.approx(ref.std_errors_prior["tx"], rel=1e-6)


@pytest.mark.parametrize("n,thick", [(3, 1.0), (5, 1.0), (12, 1.0), (12, 0.05), (80, 0.05)])
def test_closed_form_single_and_batched_paths_agree(n, thick):
    rng = np.random.default_rng(n)
    B = 20
    x = rng.uniform(-10, 10, (B, n, 3))
    x[:, :, 2] *= thick
    R = Rotation.random(B, random_state=n).as_matrix()
    X = 2.0 * np.matmul(x, np.swapaxes(R, 1, 2)) + 4 + rng.normal(scale=0.05, size=(B, n, 3))
    for nearest in (False, True):
        b = pg.absolute_orientation_batch(x, X, "closed-form", nearest_rotation=nearest)
        for i in range(B):
            f = pg.absolute_orientation(x[i], X[i], "closed-form", nearest_rotation=nearest)
            np.testing.assert_allclose(f.rotation, b.rotation[i], atol=1e-10)
            assert f.scale == pytest.approx(b.scale[i], rel=1e-12)
            np.testing.assert_allclose(f.translation, b.translation[i], atol=1e-9)
