"""RANSAC with batched minimal solves, data snooping, and the batched API."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import photogeom as pg
from photogeom.rotation import rotation_from_angles


def _wrong_correspondences(n=1000, outlier_fraction=0.5, noise=0.002, seed=7):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    s, t = 1.5, np.array([120.0, -340.0, 56.0])
    x = rng.uniform(-50, 50, (n, 3))
    X = s * x @ R.T + t + rng.normal(scale=noise, size=(n, 3))
    bad = rng.choice(n, int(outlier_fraction * n), replace=False)
    X[bad] = X[rng.permutation(bad)]  # shuffled partners: wrong correspondences
    truth = np.linalg.norm(X - (s * x @ R.T + t), axis=1) < 10 * noise
    return x, X, (s, R, t), truth


def test_ransac_recovers_transformation_and_inlier_mask():
    x, X, (s, R, t), truth = _wrong_correspondences()
    assert 480 <= (~truth).sum() <= 500  # about half are wrong
    fit = pg.ransac_absolute_orientation(x, X, threshold=0.01, rng=3)
    np.testing.assert_array_equal(fit.inliers, truth)
    np.testing.assert_allclose(fit.rotation, R, atol=1e-5)
    assert fit.scale == pytest.approx(s, rel=1e-5)
    np.testing.assert_allclose(fit.translation, t, atol=1e-3)
    assert fit.residuals.shape == (int(truth.sum()), 3)
    assert fit.extras["all_residuals"].shape == (1000, 3)
    assert fit.ids == tuple(int(i) for i in np.flatnonzero(truth))
    assert fit.sigma0 == pytest.approx(0.002, rel=0.1)
    # a least-squares method on all pairs is ruined by the wrong correspondences
    bad = pg.absolute_orientation(x, X)
    assert np.abs(bad.rotation - R).max() > 1e-2
    # the same through absolute_orientation(robust=...), refined by Gauss-Markov
    gm = pg.absolute_orientation(x, X, "gauss-markov", robust="ransac", threshold=0.01, rng=3)
    np.testing.assert_array_equal(gm.inliers, truth)
    assert gm.method == "gauss-markov"


def test_ransac_bad_input():
    x, X, _, _ = _wrong_correspondences(n=50)
    with pytest.raises(pg.InputError, match="threshold"):
        pg.ransac_absolute_orientation(x, X, threshold=0.0)
    with pytest.raises(pg.InputError, match="threshold"):
        pg.absolute_orientation(x, X, robust="ransac")
    with pytest.raises(pg.TooFewPointsError, match="inliers"):
        pg.ransac_absolute_orientation(x, X + np.arange(150).reshape(50, 3) ** 2, threshold=1e-9)


def test_data_snooping_removes_gross_error():
    rng = np.random.default_rng(4)
    R = rotation_from_angles(0.4, 1.2, -2.9)
    x = rng.uniform(-50, 50, (20, 3))
    X = 2.0 * x @ R.T + [10, 20, 30] + rng.normal(scale=0.01, size=(20, 3))
    X[6] += [0.25, -0.15, 0.1]
    fit = pg.absolute_orientation(x, X, sigma_target=0.01)
    sn = fit.snooping()  # Baarda's w-test on the direct solution's normalised residuals
    assert sn.suspect is not None and sn.suspect // 3 == 6
    for sigma, kw in (("prior", {"sigma_target": 0.01}), ("posterior", {})):
        clean = pg.snooping_absolute_orientation(x, X, sigma=sigma, **kw)
        assert clean.extras["removed"] == [6]
        assert clean.extras["kept"].sum() == 19
        assert clean.ids == tuple(i for i in range(20) if i != 6) or clean.ids is None
    ok = pg.snooping_absolute_orientation(np.delete(x, 6, 0), np.delete(X, 6, 0), "svd")
    assert ok.extras["removed"] == []


def test_batch_matches_single_solves_and_flags_bad_problems():
    rng = np.random.default_rng(5)
    B, n = 40, 6
    x = rng.normal(scale=10, size=(B, n, 3))
    R = Rotation.random(B, random_state=5).as_matrix()
    X = np.matmul(x, np.swapaxes(R, 1, 2)) * 3 + 7 + rng.normal(scale=0.05, size=(B, n, 3))
    x[3] = np.outer(np.arange(n), [1.0, 2.0, 3.0])  # collinear
    X[3] = x[3]
    X[5] = x[5] * [1, 1, -1]  # mirror image: a reflection
    w = rng.uniform(0.5, 2, (B, n))
    for m in ("svd", "quaternion", "dual-quaternion", "closed-form", "gauss-helmert"):
        res = pg.absolute_orientation_batch(x, X, m, residual_rms=True)
        assert res.degenerate[3] and not res.valid[3], m
        assert np.isnan(res.rotation[3]).all()
        assert res.reflection[5] and not res.valid[5], m
        assert res.valid.sum() == B - 2
        for i in (0, 7, 39):
            single = pg.absolute_orientation(x[i], X[i], m)
            np.testing.assert_allclose(res.rotation[i], single.rotation, atol=1e-9)
            assert res.scale[i] == pytest.approx(single.scale, rel=1e-9)
            np.testing.assert_allclose(res.translation[i], single.translation, atol=1e-8)
            v = single.transform.apply(x[i]) - X[i]  # transfer residuals (GH: misclosures)
            assert res.rms[i] == pytest.approx(np.sqrt(np.sum(v * v) / n), rel=1e-9)
        assert res.transform(0).apply(x[0]).shape == (n, 3)
        with pytest.raises(pg.InputError, match="no valid estimate"):
            res.transform(3)
    wres = pg.absolute_orientation_batch(x, X, "svd", weights=w)
    single = pg.absolute_orientation(x[0], X[0], "svd", weights=w[0])
    np.testing.assert_allclose(wres.rotation[0], single.rotation, atol=1e-9)
    omega = wres.angles("direct", "deg")[0]
    assert np.isnan(omega[3]) and np.isfinite(omega[0])


def test_batch_bad_input():
    x = np.zeros((4, 5, 3))
    with pytest.raises(pg.InputError, match=r"\(B, n, 3\)"):
        pg.absolute_orientation_batch(x[0], x[0])
    with pytest.raises(pg.InputError, match="same shape"):
        pg.absolute_orientation_batch(x, x[:, :4])
    with pytest.raises(pg.TooFewPointsError, match="at least 3"):
        pg.absolute_orientation_batch(x[:, :2], x[:, :2])
    y = np.random.default_rng(0).normal(size=(4, 5, 3))
    z = y.copy()
    z[2, 1, 0] = np.nan
    with pytest.raises(pg.InputError, match="problem index 2"):
        pg.absolute_orientation_batch(y, z)
    with pytest.raises(pg.InputError, match="not available in batches"):
        pg.absolute_orientation_batch(y, y, "gauss-markov")
    with pytest.raises(pg.InputError, match="no weights"):
        pg.absolute_orientation_batch(y, y, "closed-form", weights=np.ones(5))


def test_batch_exactly_coplanar_noisy_sets():
    """sigma3(H) at round-off level: the batched SVD must still return proper rotations."""
    rng = np.random.default_rng(9)
    B = 300
    R = Rotation.random(B, random_state=9).as_matrix()
    x = rng.uniform(-50, 50, (B, 10, 3))
    x[:, :, 2] = 0.0
    X = 1.5 * np.matmul(x, np.swapaxes(R, 1, 2)) + 3 + rng.normal(scale=0.01, size=(B, 10, 3))
    q = pg.absolute_orientation_batch(x, X, "quaternion")
    for m in ("svd", "gauss-helmert", "dual-quaternion"):
        r = pg.absolute_orientation_batch(x, X, m)
        assert r.valid.all()
        np.testing.assert_allclose(r.rotation, q.rotation, atol=1e-9, err_msg=m)
    np.testing.assert_allclose(
        np.linalg.det(pg.absolute_orientation_batch(x, X, "svd").rotation), 1.0, atol=1e-12
    )
