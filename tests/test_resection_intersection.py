"""Space intersection: exact recovery, independent Gauss-Markov check, Monte Carlo, bad input."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import ConvergenceError, DegenerateGeometryError, InputError

IO = pg.InteriorOrientation(152.0, 0.01, -0.02, distortion=pg.BrownDistortion(k1=-0.03, p1=1e-4))
EOS = [
    pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10),
    pg.ExteriorOrientation.from_degrees(1600, 820, 1620, -1, 2, 8),
    pg.ExteriorOrientation.from_degrees(1300, 1300, 1580, 3, -2, 95),
]


def ground(n, rng):
    return np.column_stack(
        [rng.uniform(1050, 1550, n), rng.uniform(750, 1100, n), rng.uniform(100, 300, n)]
    )


def observe(g, eos=EOS, io=IO):
    return np.stack([pg.project(g, io, e) for e in eos])


def test_noise_free_points_are_recovered():
    rng = np.random.default_rng(0)
    g = ground(2000, rng)
    res = pg.space_intersection(observe(g), [(IO, e) for e in EOS])
    np.testing.assert_allclose(res.points, g, rtol=0, atol=1e-7)
    assert res.converged.all() and np.all(res.redundancy == 3) and np.all(res.n_rays == 3)
    # FrameCamera objects work as well, and two images suffice
    cams = [pg.FrameCamera(IO, e) for e in EOS[:2]]
    res2 = pg.space_intersection(observe(g[:10], EOS[:2]), cams)
    np.testing.assert_allclose(res2.points, g[:10], atol=1e-7)
    assert np.all(res2.redundancy == 1)


def test_agrees_with_gauss_markov_engine():
    # Independent path: the general Gauss-Markov adjustment with a numerical Jacobian.
    rng = np.random.default_rng(1)
    g = ground(3, rng)
    sigma = 0.003
    io0 = IO.with_distortion(None)
    obs = observe(g, io=io0) + rng.normal(0, sigma, (3, 3, 2))
    res = pg.space_intersection(obs, [(io0, e) for e in EOS], sigma=sigma)
    for j in range(3):

        def model(X):
            return np.concatenate([pg.project(X, io0, e) for e in EOS])

        adj = pg.gauss_markov(
            model, g[j] + 5.0, obs[:, j].reshape(-1), weights=np.full(6, sigma**-2)
        )
        np.testing.assert_allclose(res.points[j], adj.x, rtol=0, atol=1e-8)
        np.testing.assert_allclose(res.cofactor[j], adj.cofactor, rtol=1e-6)
        assert res.sigma0[j] == pytest.approx(adj.sigma0, rel=1e-6)
        np.testing.assert_allclose(res.residuals[:, j], adj.residuals.reshape(3, 2), atol=1e-9)


def test_covariance_matches_monte_carlo():
    rng = np.random.default_rng(2)
    sigma = 0.004
    trials = 4000
    g = np.tile(ground(1, rng), (trials, 1))
    obs = observe(g) + rng.normal(0, sigma, (3, trials, 2))
    res = pg.space_intersection(obs, [(IO, e) for e in EOS], sigma=sigma)
    spread = res.points.std(axis=0, ddof=1)
    np.testing.assert_allclose(spread / res.std_prior.mean(axis=0), 1.0, atol=0.10)
    C = np.cov(res.points.T)
    np.testing.assert_allclose(C, res.covariance_prior.mean(axis=0), atol=0.15 * np.abs(C).max())
    assert np.mean(res.sigma0**2) == pytest.approx(1.0, abs=0.08)


def test_missing_observations_and_too_few_rays():
    rng = np.random.default_rng(3)
    g = ground(6, rng)
    obs = observe(g)
    obs[0, :2] = np.nan  # points 0 and 1 only in images 2 and 3
    res = pg.space_intersection(obs, [(IO, e) for e in EOS])
    assert res.n_rays.tolist() == [2, 2, 3, 3, 3, 3]
    assert np.all(np.isnan(res.residuals[0, :2]))
    np.testing.assert_allclose(res.points, g, atol=1e-7)
    obs[1, 0] = np.nan
    with pytest.raises(InputError, match=r"fewer than 2 images \(point index 0\)"):
        pg.space_intersection(obs, [(IO, e) for e in EOS])
    with pytest.raises(InputError, match="2 camera"):
        pg.space_intersection(observe(g), [(IO, e) for e in EOS[:2]])


def test_parallel_rays_are_refused():
    io = pg.InteriorOrientation(100.0)
    eos = [pg.ExteriorOrientation(0, 0, 1000), pg.ExteriorOrientation(0, 0, 2000)]
    obs = np.zeros((2, 1, 2))  # the same nadir ray in both images
    with pytest.raises(DegenerateGeometryError, match="parallel"):
        pg.space_intersection(obs, [(io, e) for e in eos])


def test_undistortion_failure_is_reported():
    io = pg.InteriorOrientation(100.0, distortion=pg.BrownDistortion(k1=-0.5))
    obs = np.array([[[80.0, 0.0]], [[0.0, 0.0]]])  # first far beyond the fold-over radius
    with pytest.raises(ConvergenceError, match="undistortion"):
        pg.space_intersection(obs, [(io, EOS[0]), (io, EOS[1])])
