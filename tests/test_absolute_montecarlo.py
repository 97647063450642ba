"""Reported standard deviations against the spread of 1000 Monte-Carlo trials (seeded).

The trials are solved in one vectorised call of the batched solver, which gives the same
estimate as the adjustment (SVD = converged Gauss-Markov for isotropic point weights; the
direct Gauss-Helmert solution = the iterative one for one sigma per system).
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.rotation import rotation_from_angles

TRIALS = 1000
NAMES = ("tx", "ty", "tz", "scale", "omega", "phi", "kappa")


def _setup(seed=2024, n=10):
    rng = np.random.default_rng(seed)
    R = rotation_from_angles(2.6, -0.7, -2.2)  # large angles, transposed convention
    s = 1.7
    t = np.array([4.2e5, 5.1e6, 310.0])
    x = rng.uniform(-30, 30, (n, 3)) + np.array([100.0, -50.0, 20.0])
    return rng, x, s, R, t


def _params(res) -> np.ndarray:
    w, p, k = res.angles("transposed", "rad")
    return np.column_stack([res.translation, res.scale, w, p, k])


def _compare(reported: dict, est: np.ndarray, truth: np.ndarray):
    d = est - truth
    d[:, 4:] = (d[:, 4:] + np.pi) % (2 * np.pi) - np.pi
    emp = d.std(axis=0, ddof=1)
    rep = np.array([reported[k] for k in NAMES])
    ratio = emp / rep
    assert np.all(np.abs(ratio - 1) < 0.10), dict(zip(NAMES, ratio.round(3)))
    # and the estimator is unbiased at this noise level
    assert np.all(np.abs(d.mean(axis=0)) < 4 * emp / np.sqrt(len(d)) + 1e-12)


def test_gauss_markov_std_match_monte_carlo():
    rng, x, s, R, t = _setup()
    sigma = 0.02
    X0 = s * x @ R.T + t
    truth = np.r_[t, s, pg.angles_from_rotation(R, "transposed")]
    Xt = X0[None] + rng.normal(scale=sigma, size=(TRIALS, *X0.shape))
    xt = np.broadcast_to(x, Xt.shape)
    est = pg.absolute_orientation_batch(xt, Xt, "svd")
    assert est.valid.all()
    gm = pg.absolute_orientation(x, Xt[0], "gauss-markov", sigma_target=sigma)
    svd = pg.absolute_orientation(x, Xt[0], "svd", sigma_target=sigma)
    for fit in (gm, svd):
        _compare(fit.std_errors_prior, _params(est), truth)
    # sigma0^2 is unbiased: its mean over the trials is 1 (a priori sigma known)
    rms = pg.absolute_orientation_batch(xt, Xt, "svd", residual_rms=True).rms
    s02 = rms**2 * x.shape[0] / sigma**2 / (3 * x.shape[0] - 7)
    assert s02.mean() == pytest.approx(1.0, abs=0.05)


def test_gauss_helmert_std_match_monte_carlo():
    rng, x, s, R, t = _setup(seed=99)
    sx, sX = 0.01, 0.03
    X0 = s * x @ R.T + t
    truth = np.r_[t, s, pg.angles_from_rotation(R, "transposed")]
    xt = x[None] + rng.normal(scale=sx, size=(TRIALS, *x.shape))
    Xt = X0[None] + rng.normal(scale=sX, size=(TRIALS, *X0.shape))
    est = pg.absolute_orientation_batch(xt, Xt, "gauss-helmert", sigma_source=sx, sigma_target=sX)
    assert est.valid.all()
    gh = pg.absolute_orientation(xt[0], Xt[0], "gauss-helmert", sigma_source=sx, sigma_target=sX)
    _compare(gh.std_errors_prior, _params(est), truth)
    # the iterative adjustment reports the same standard deviations
    it = pg.absolute_orientation(
        xt[0], Xt[0], "gauss-helmert", sigma_source=sx, sigma_target=sX, iterate=True
    )
    for k in NAMES:
        assert it.std_errors_prior[k] == pytest.approx(gh.std_errors_prior[k], rel=1e-8)


def _published_params(res) -> np.ndarray:
    from photogeom.orientation.absolute_direct import published_angles

    w, p, k = published_angles(res.rotation, "transposed")
    return np.column_stack([res.translation, res.scale, w, p, k])


@pytest.mark.parametrize(
    "n,nearest", [(10, False), (3, False), (10, True)], ids=["raw", "three-points", "nearest"]
)
def test_closed_form_std_match_monte_carlo(n, nearest):
    # the closed form is not least squares: its standard deviations are propagated through
    # the estimator (the linearised least-squares ones were 0.61-0.91 of the spread)
    rng, x, s, R, t = _setup(seed=5, n=n)
    sigma = 0.05
    X0 = s * x @ R.T + t
    truth = np.r_[t, s, pg.angles_from_rotation(R, "transposed")]
    Xt = X0[None] + rng.normal(scale=sigma, size=(TRIALS, *X0.shape))
    xt = np.broadcast_to(x, Xt.shape)
    est = pg.absolute_orientation_batch(xt, Xt, "closed-form", nearest_rotation=nearest)
    assert est.valid.all()
    fit = pg.absolute_orientation(
        x, Xt[0], "closed-form", sigma_target=sigma, nearest_rotation=nearest
    )
    assert any("propagated through the closed-form" in note for note in fit.notes)
    _compare(fit.std_errors_prior, _params(est) if nearest else _published_params(est), truth)


@pytest.mark.parametrize("method", ["quaternion", "dual-quaternion"])
def test_other_direct_methods_std_match_monte_carlo(method):
    rng, x, s, R, t = _setup(seed=6)
    sigma = 0.02
    X0 = s * x @ R.T + t
    truth = np.r_[t, s, pg.angles_from_rotation(R, "transposed")]
    Xt = X0[None] + rng.normal(scale=sigma, size=(TRIALS, *X0.shape))
    est = pg.absolute_orientation_batch(np.broadcast_to(x, Xt.shape), Xt, method)
    fit = pg.absolute_orientation(x, Xt[0], method, sigma_target=sigma)
    _compare(fit.std_errors_prior, _params(est), truth)
