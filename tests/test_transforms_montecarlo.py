"""Reported standard deviations against the spread of Monte-Carlo trials (2D similarity and
affine; parametric and textbook parameters; weighted observations; UTM-sized shifts).

The trials are batched: a linear least-squares estimator is an affine function of the
observations, so its response to each observation is measured once on the library's
estimator (2n + 1 runs) and applied to all trials at once; that the response is exactly
affine is checked on real runs of the estimator for a subset of the trials. Textbook
parameters are converted trial by trial with the models' own (nonlinear) conversions.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg

TRIALS = 2000
SIGMA = 0.05
N = 10


def response(model, src, clean, w):
    """Parameters and residuals of the estimator as affine functions of the target noise."""
    base = pg.estimate_transform(model, src, clean, weights=w, sigma0_prior=SIGMA)
    G, V = [], []
    for j in range(2 * N):
        e = np.zeros(2 * N)
        e[j] = 1.0
        f = pg.estimate_transform(model, src, clean + e.reshape(N, 2), weights=w,
                                  sigma0_prior=SIGMA)
        G.append(f.parameters - base.parameters)
        V.append((f.residuals - base.residuals).reshape(-1))
    return base, np.array(G).T, np.array(V).T


@pytest.mark.parametrize(
    "model, true",
    [
        ("similarity2d", pg.Similarity2D.from_textbook(1.25, np.radians(140.0), 3.0e5, 4.1e6)),
        ("affine2d", pg.Affine2D.from_textbook(0.8, 1.3, np.radians(-100.0), np.radians(7.0),
                                               3.0e5, 4.1e6)),
    ],
)
def test_standard_deviations_match_monte_carlo(model, true):
    rng = np.random.default_rng(20240607)
    src = rng.uniform(-400, 400, (N, 2)) + np.array([5000.0, -2000.0])
    w = rng.uniform(0.5, 4.0, N)  # per-point weights: sigma_i = SIGMA / sqrt(w_i)
    clean = true.apply(src)
    base, G, V = response(model, src, clean, w)
    noise = (rng.normal(size=(TRIALS, N, 2)) * (SIGMA / np.sqrt(w))[None, :, None])
    noise = noise.reshape(TRIALS, -1)
    params = base.parameters + noise @ G.T
    resid = base.residuals.reshape(-1) + noise @ V.T

    # the batched trials are the estimator's results (checked on real runs)
    for k in range(15):
        f = pg.estimate_transform(model, src, clean + noise[k].reshape(N, 2), weights=w,
                                  sigma0_prior=SIGMA)
        np.testing.assert_allclose(f.parameters, params[k], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(f.residuals.reshape(-1), resid[k], atol=1e-9)

    # parametric parameters: a-priori standard deviations vs spread, within 10 %
    predicted = np.array(list(base.std_errors_prior.values()))
    observed = params.std(axis=0, ddof=1)
    np.testing.assert_allclose(observed / predicted, 1.0, atol=0.10)
    # the whole covariance: correlations agree too
    np.testing.assert_allclose(np.corrcoef(params.T), base.correlation, atol=0.06)
    # unbiased: means within 4 standard errors of the mean
    assert np.all(np.abs(params.mean(axis=0) - true.parameters) < 4 * predicted / np.sqrt(TRIALS))

    # textbook parameters (scale(s), angles, shifts) by first-order error propagation
    names = list(base.extras["textbook"])
    textbook = np.array([list(base.model.with_parameters(p).textbook().values())
                         for p in params])
    tb_pred = SIGMA * np.sqrt(np.diag(base.extras["textbook_cofactor"]))
    np.testing.assert_allclose(textbook.std(axis=0, ddof=1) / tb_pred, 1.0, atol=0.10,
                               err_msg=str(names))
    # a-posteriori standard deviations of the textbook parameters use sigma0
    np.testing.assert_allclose([base.extras["textbook"][n][1] for n in names],
                               base.sigma0 * tb_pred / SIGMA, rtol=1e-9)

    # the a-posteriori variance factor v.T P v / r estimates SIGMA^2
    vtpv = np.sum(resid**2 * np.repeat(w, 2), axis=1)
    assert np.mean(vtpv / base.redundancy) / SIGMA**2 == pytest.approx(1.0, abs=0.05)
