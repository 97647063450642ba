"""Gauss-Helmert absolute orientation without stated precisions: every coordinate of a system
whose precision is not given has weight 1, i.e. the standard deviation ``sigma0_prior``
(the docstring of :func:`photogeom.absolute_orientation` and the note of the fit say so).

Checked against the same fit with the precision stated (an independent path through the
input handling), and against the spread of redraws of the noise in both systems.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg

SIGMA = 0.01
NAMES = ("tx", "ty", "tz", "scale", "omega", "phi", "kappa")


def _scene(seed=7, n=10):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-50.0, 50.0, (n, 3))
    R = pg.opk_matrix(*np.radians([20.0, 30.0, 160.0])).T
    X = 1.2 * x @ R.T + np.array([4.0e5, 5.1e6, 300.0])
    return rng, x, X


@pytest.mark.parametrize("iterate", [None, True])
@pytest.mark.parametrize(
    "given, stated",
    [
        ({}, {"sigma_source": SIGMA, "sigma_target": SIGMA}),
        ({"sigma_target": 0.03}, {"sigma_source": SIGMA, "sigma_target": 0.03}),
        ({"sigma_source": 0.002}, {"sigma_source": 0.002, "sigma_target": SIGMA}),
    ],
)
def test_missing_precision_is_sigma0_prior(given, stated, iterate):
    rng, x, X = _scene()
    xs = x + rng.normal(0.0, SIGMA, x.shape)
    Xs = X + rng.normal(0.0, SIGMA, X.shape)
    kw = {"sigma0_prior": SIGMA, "iterate": iterate}
    a = pg.absolute_orientation(xs, Xs, "gauss-helmert", **given, **kw)
    b = pg.absolute_orientation(xs, Xs, "gauss-helmert", **stated, **kw)
    np.testing.assert_allclose(a.parameters, b.parameters, rtol=1e-9, atol=1e-9)
    assert a.sigma0 == pytest.approx(b.sigma0, rel=1e-6)
    np.testing.assert_allclose(a.covariance_prior, b.covariance_prior, rtol=1e-6, atol=1e-30)
    np.testing.assert_allclose(a.normalized_residuals, b.normalized_residuals, rtol=1e-6,
                               atol=1e-9)  # fmt: skip


def test_sigma0_and_prior_std_follow_the_redraws():
    """Noise of SIGMA in both systems, only ``sigma0_prior=SIGMA`` given: the mean of
    (sigma0 / sigma0_prior)^2 over 200 redraws is 1 (sampling error sqrt(2 / (200 r)) = 1.8 %)
    and the spread of every parameter is its a-priori standard deviation (about 5 %)."""
    rng, x, X = _scene(seed=11)
    fits = [
        pg.absolute_orientation(x + rng.normal(0.0, SIGMA, x.shape),
                                X + rng.normal(0.0, SIGMA, X.shape), "gauss-helmert",
                                sigma0_prior=SIGMA)
        for _ in range(200)
    ]  # fmt: skip
    s02 = np.mean([(f.sigma0 / f.sigma0_prior) ** 2 for f in fits])
    assert s02 == pytest.approx(1.0, abs=0.08)
    P = np.array([f.parameters for f in fits])
    P[:, 4:] = P[0, 4:] + (P[:, 4:] - P[0, 4:] + np.pi) % (2 * np.pi) - np.pi
    std = np.array([fits[0].std_errors_prior[k] for k in NAMES])
    ratio = P.std(axis=0, ddof=1) / std
    assert np.all((ratio > 0.8) & (ratio < 1.2)), dict(zip(NAMES, ratio.round(3)))
    w = np.abs(np.array([f.normalized_residuals for f in fits]))
    assert np.mean(w > 1.959964) == pytest.approx(0.05, abs=0.015)
