"""Terrain-dependent RPC fits with a Tikhonov penalty: the reported standard deviations of
the coefficients against the spread of Monte-Carlo redraws of the image noise.

The estimate ``x = Q A^T P l`` with ``Q = (A^T P A + W)^-1`` (``W`` the weights of the
pseudo-observations ``c_j = 0``) varies with the noise as ``Q (A^T P A) Q``. Before, ``Q``
itself was reported: with the regularization suggested for noisy points (1e-3, order 2, 40
points, 0.5 px, 300 redraws) the spread of most denominator and higher-order coefficients
was 0.07-0.2 times their reported standard deviations (those 5-14 times too large).
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from photogeom.rpc import fit_rpc_to_points
from photogeom.rpc.fitting import NOISY_REGULARIZATION

sys.path.insert(0, str(Path(__file__).parent))
from rpc_samples import ikonos_points

SIGMA = 0.5  # px


@pytest.fixture(scope="module")
def scene():
    """40 points whose image positions an order-2 RPC fits exactly (the regularised fit to
    the vendor model's positions, evaluated at the points)."""
    G, im = ikonos_points(np.random.default_rng(240), 40)
    truth = fit_rpc_to_points(G, im, order=2, regularization=NOISY_REGULARIZATION).model
    return G, np.column_stack(truth.project(*G.T, domain_limit=None))


def test_coefficient_std_follow_the_redraws(scene):
    G, im = scene
    rng = np.random.default_rng(7)
    fits = [
        fit_rpc_to_points(G, im + rng.normal(0.0, SIGMA, im.shape), order=2, sigma=SIGMA,
                          regularization=NOISY_REGULARIZATION)
        for _ in range(300)
    ]  # fmt: skip
    P = np.array([f.parameters for f in fits])
    std = np.sqrt(np.mean([np.diag(f.covariance) for f in fits], axis=0))
    ratio = P.std(axis=0, ddof=1) / std
    names = fits[0].parameter_names
    # the constant terms of the numerators follow the offsets SAMP_OFF, LINE_OFF, which are
    # taken from the points' image range and so move with the noise (their standard
    # deviations hold for the offsets as fitted)
    other = np.array([n not in ("SAMP_NUM_1", "LINE_NUM_1") for n in names])
    # a standard deviation from 300 redraws scatters by about 4 %; before: median 0.2,
    # smallest 0.07
    assert np.median(ratio[other]) == pytest.approx(1.0, abs=0.08)
    assert np.all((ratio[other] > 0.8) & (ratio[other] < 1.3)), dict(zip(names, ratio.round(2)))
    # sigma0 (effective redundancy) was already right and stays so
    assert np.mean([f.sigma0**2 for f in fits]) == pytest.approx(1.0, abs=0.05)


def test_cofactor_is_the_sandwich_of_the_regularised_estimate(scene):
    """``Q (A^T P A) Q`` with ``A`` the derivatives of the image positions (px) with respect
    to the coefficients, taken here by central differences of RPC.project; the same for
    every sigma up to the factor sigma^2."""
    G, im = scene
    noisy = im + np.random.default_rng(3).normal(0.0, SIGMA, im.shape)
    lam = NOISY_REGULARIZATION
    fits = [fit_rpc_to_points(G, noisy, order=2, sigma=s, regularization=lam) for s in (1.0, 5.0)]
    # (the two iterations stop a few 1e-6 apart relative)
    np.testing.assert_allclose(fits[1].cofactor, 25.0 * fits[0].cofactor, rtol=1e-4,
                               atol=1e-8 * np.abs(fits[1].cofactor).max())  # fmt: skip
    fit = fits[0]
    rpc = fit.model
    k = fit.parameters.size // 2
    nt = (k + 1) // 2
    cols = []
    for j in range(2 * k):
        out = []
        for sign in (1.0, -1.0):
            x = fit.parameters.copy()
            x[j] += sign * 1e-7
            c, p = x[:k], x[k:]
            sn, ln = np.zeros(20), np.zeros(20)
            sd, ld = np.zeros(20), np.zeros(20)
            sn[:nt], sd[0], sd[1:nt] = c[:nt], 1.0, c[nt:]
            ln[:nt], ld[0], ld[1:nt] = p[:nt], 1.0, p[nt:]
            m = replace(rpc, samp_num=sn, samp_den=sd, line_num=ln, line_den=ld)
            out.append(np.concatenate(m.project(*G.T, domain_limit=None)))
        cols.append((out[0] - out[1]) / 2e-7)
    A = np.column_stack(cols)  # (2n, 2k): cols then rows
    N = A.T @ A  # sigma = 1
    S = np.repeat([rpc.samp_scale, rpc.line_scale], k)
    Q = np.linalg.inv(N + np.diag((lam * S) ** 2))
    expected = Q @ N @ Q
    sd = np.sqrt(np.diag(expected))
    # differences of 1e-7 in the coefficients: agreement to about 1e-5
    np.testing.assert_allclose(np.sqrt(np.diag(fit.cofactor)), sd, rtol=1e-3)
    np.testing.assert_allclose(fit.cofactor / np.outer(sd, sd), expected / np.outer(sd, sd),
                               atol=1e-4)  # fmt: skip
