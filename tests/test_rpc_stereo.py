"""Stereo intersection from RPC images: exactness, covariance vs Monte Carlo, the engine."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError, TooFewPointsError
from photogeom.rpc import RPC, LocalizationWarning, intersect_rpc


@pytest.fixture(scope="module")
def pair():
    """IKONOS and Pleiades images of Montevideo (overlapping footprints)."""
    return RPC.from_file(pg.datasets.path("ikonos")), RPC.from_file(pg.datasets.path("pleiades"))


def ground_points(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([
        rng.uniform(-56.22, -56.12, n), rng.uniform(-34.94, -34.86, n), rng.uniform(0, 100, n)
    ])  # fmt: skip


def observe(rpcs, G):
    return np.stack([np.column_stack(r.project(*G.T)) for r in rpcs], axis=1)


def test_noise_free_points_are_recovered(pair):
    G = ground_points(200, 1)
    res = intersect_rpc(pair, observe(pair, G))
    assert res.converged.all()
    assert np.max(np.abs(res.ground[:, :2] - G[:, :2])) < 1e-10
    assert np.max(np.abs(res.h - G[:, 2])) < 1e-5
    assert np.nanmax(np.abs(res.residuals)) < 1e-6
    assert res.redundancy.tolist() == [1] * 200
    # a list of per-image arrays works too
    obs = observe(pair, G[:3])
    res2 = intersect_rpc(pair, [obs[:, 0], obs[:, 1]])
    np.testing.assert_allclose(res2.ground, res.ground[:3], atol=1e-10)


def test_covariance_matches_monte_carlo_spread(pair):
    # one ground point observed 4000 times with noise: the vectorised intersection is the
    # Monte-Carlo batch
    sigma = 0.5
    G = ground_points(1, 2)
    trials = 4000
    rng = np.random.default_rng(12)
    obs = np.repeat(observe(pair, G), trials, axis=0) + rng.normal(0, sigma, (trials, 2, 2))
    res = intersect_rpc(pair, obs, sigma=sigma)
    assert res.converged.all()
    mc = np.std(res.ground, axis=0, ddof=1)
    predicted = res.std_prior.mean(axis=0)
    np.testing.assert_allclose(predicted, mc, rtol=0.10)
    # mean of sigma0^2 is 1 (r = 1 per point)
    assert np.mean(res.sigma0**2) == pytest.approx(1.0, abs=0.1)
    # metric standard deviations: degrees scaled by the radii of curvature
    m = res.std_metric()[0]
    assert m[0] == pytest.approx(
        np.radians(predicted[0]) * 6.38e6 * np.cos(np.radians(G[0, 1])), rel=0.01
    )
    assert m[2] == pytest.approx(res.std_prior[0, 2])


def test_agrees_with_the_gauss_markov_engine(pair):
    G = ground_points(3, 3)
    rng = np.random.default_rng(4)
    obs = observe(pair, G) + rng.normal(0, 0.7, (3, 2, 2))
    sig = np.array([0.5, 0.8])  # per image
    res = intersect_rpc(pair, obs, sigma=sig)
    for i in range(3):

        def model(x):
            return np.concatenate([np.array(r.project(*x)) for r in pair])

        w = np.repeat(1.0 / sig**2, 2)
        adj = pg.gauss_markov(model, res.ground[i] + [1e-5, -1e-5, 5.0], obs[i].reshape(-1),
                              weights=w, what="one RPC intersection")  # fmt: skip
        assert np.all(np.abs(adj.x - res.ground[i]) < [1e-10, 1e-10, 1e-6])
        np.testing.assert_allclose(adj.cofactor, res.cofactor[i], rtol=1e-4)
        assert adj.sigma0 == pytest.approx(res.sigma0[i], rel=1e-5)


def test_points_missing_in_some_images(pair):
    a, b = pair
    G = ground_points(4, 5)
    obs = np.stack([observe(pair, G)[:, 0], observe(pair, G)[:, 1], observe(pair, G)[:, 0]], 1)
    obs[0, 2] = np.nan  # point 0 not seen in image 3
    res = intersect_rpc([a, b, a], obs)
    assert res.redundancy.tolist() == [1, 3, 3, 3]
    assert np.all(np.isnan(res.residuals[0, 2]))
    assert np.max(np.abs(res.ground[:, :2] - G[:, :2])) < 1e-10
    obs[1, 1] = np.nan
    obs[1, 2] = np.nan
    with pytest.raises(TooFewPointsError, match="point\\(s\\) 1"):
        intersect_rpc([a, b, a], obs)


def test_bad_input(pair):
    a, _ = pair
    with pytest.raises(TooFewPointsError, match="images"):
        intersect_rpc([a], np.zeros((2, 1, 2)))
    with pytest.raises(InputError, match="shape"):
        intersect_rpc(pair, np.zeros((2, 3, 2)))
    with pytest.raises(InputError, match="sigma"):
        intersect_rpc(pair, observe(pair, ground_points(2, 0)), sigma=[1.0, -1.0])


def test_non_converging_points_are_nan_with_status(pair):
    G = ground_points(2, 6)
    obs = observe(pair, G)
    with pytest.warns(LocalizationWarning, match="did not converge"):
        res = intersect_rpc(pair, obs, max_iter=1, tol=1e-30)
    assert not res.converged.any() and np.all(np.isnan(res.ground))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ok = intersect_rpc(pair, obs)
    assert ok.converged.all()
    with pytest.raises(pg.ConvergenceError):
        intersect_rpc(pair, obs, max_iter=1, tol=1e-30, on_failure="raise")
