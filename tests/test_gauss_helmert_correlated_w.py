"""Baarda's w-test of Gauss-Helmert adjustments with correlated observations (per-point or
full covariances): redundancy numbers diag(Qvv P) and w = (P v)_i / (sigma0_prior
sqrt((P Qvv P)_ii)), as the Gauss-Markov engine gives them. Checked against the diagonal
path (the same precision as standard deviations), against the Gauss-Markov model (source
covariance -> 0), against redraws (5 % rejected, the redundancy numbers sum to r) and by data
snooping finding a blunder.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.orientation import snooping_absolute_orientation

N = 10


def _scene(seed=1):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-50.0, 50.0, (N, 3))
    R = pg.opk_matrix(*np.radians([170.0, 20.0, -170.0])).T
    return rng, x, 1.2 * x @ R.T + np.array([4.0e5, 5.0e6, 300.0])


def _covariances(rng, scale):
    A = rng.normal(size=(N, 3, 3))
    return (np.einsum("nij,nkj->nik", A, A) + 0.5 * np.eye(3)) * scale**2


def _draw(rng, points, C):
    return points + np.einsum("nij,nj->ni", np.linalg.cholesky(C), rng.normal(size=(N, 3)))


def test_diagonal_covariances_give_the_w_of_the_standard_deviations():
    rng, x, X = _scene()
    ss, st = rng.uniform(0.002, 0.005, (N, 3)), rng.uniform(0.005, 0.02, (N, 3))
    xs, Xs = x + rng.normal(size=x.shape) * ss, X + rng.normal(size=X.shape) * st
    a = pg.absolute_orientation(xs, Xs, "gauss-helmert", sigma_source=ss, sigma_target=st)
    b = pg.absolute_orientation(
        xs, Xs, "gauss-helmert", covariance_source=np.einsum("ni,ij->nij", ss**2, np.eye(3)),
        covariance_target=np.einsum("ni,ij->nij", st**2, np.eye(3)),
    )
    np.testing.assert_allclose(b.normalized_residuals, a.normalized_residuals, atol=1e-9)
    np.testing.assert_allclose(b.redundancy_numbers, a.redundancy_numbers, atol=1e-12)
    np.testing.assert_allclose(b.extras["source_normalized_residuals"],
                               a.extras["source_normalized_residuals"], atol=1e-9)  # fmt: skip


def test_error_free_source_gives_the_gauss_markov_w():
    rng, x, X = _scene(2)
    Ct = _covariances(rng, 0.01)
    Xs = _draw(rng, X, Ct)
    gh = pg.absolute_orientation(x, Xs, "gauss-helmert", covariance_source=_covariances(rng, 1e-8),
                                 covariance_target=Ct)  # fmt: skip
    gm = pg.absolute_orientation(x, Xs, "gauss-markov", covariance_target=Ct)
    np.testing.assert_allclose(gh.normalized_residuals, gm.normalized_residuals, atol=1e-6)
    np.testing.assert_allclose(gh.redundancy_numbers, gm.redundancy_numbers, atol=1e-8)


def test_w_of_correlated_observations_follow_the_redraws():
    """120 redraws: 5 % of |w| above 1.96 in each system (1.5 % allowed), the redundancy
    numbers of both systems sum to r."""
    rng, x, X = _scene(3)
    Cs, Ct = _covariances(rng, 0.003), _covariances(rng, 0.01)
    w_t, w_s = [], []
    for _ in range(120):
        f = pg.absolute_orientation(_draw(rng, x, Cs), _draw(rng, X, Ct), "gauss-helmert",
                                    covariance_source=Cs, covariance_target=Ct)  # fmt: skip
        w_t.append(f.normalized_residuals)
        w_s.append(f.extras["source_normalized_residuals"])
    total = f.redundancy_numbers.sum() + f.extras["source_redundancy_numbers"].sum()
    assert total == pytest.approx(f.redundancy, rel=1e-9)
    assert np.mean(np.abs(w_t) > 1.959964) == pytest.approx(0.05, abs=0.015)
    assert np.mean(np.abs(w_s) > 1.959964) == pytest.approx(0.05, abs=0.015)


def test_snooping_with_covariances_removes_the_blunder():
    rng, x, X = _scene(4)
    Cs, Ct = _covariances(rng, 0.003), _covariances(rng, 0.01)
    Xs = _draw(rng, X, Ct)
    Xs[3] += [0.3, 0.0, 0.0]
    fit = snooping_absolute_orientation(_draw(rng, x, Cs), Xs, "gauss-helmert", sigma="prior",
                                        covariance_source=Cs, covariance_target=Ct)  # fmt: skip
    assert fit.extras["removed"] == [3]
    # and the projective transformation with errors in both systems has its w as well
    src = rng.uniform(0.0, 100.0, (12, 2))
    dst = src @ np.array([[1.1, 0.05], [0.02, 0.97]]).T + 3.0
    C = np.tile(np.diag([1e-4, 1e-4, 4e-4, 4e-4]) + 5e-5 * (1 - np.eye(4)), (12, 1, 1))
    tf = pg.estimate_transform("projective2d", src, dst + rng.normal(0.0, 0.02, dst.shape),
                               errors_in="both", covariance=C)  # fmt: skip
    assert tf.normalized_residuals is not None and np.all(np.isfinite(tf.normalized_residuals))
