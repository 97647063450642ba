"""The engine's solver paths: QR with the cheap condition certificate, corrected semi-normal
equations for tall problems, blocked QR, statistics from the factor, statistics=False, and the
Gauss-Newton step control."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from photogeom.adjust import gauss_markov, solve_linear
from photogeom.errors import DegenerateGeometryError

gm = importlib.import_module("photogeom.adjust.gauss_markov")


def _tall(m=6000, u=5, seed=0, cond=None):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, u)) * rng.uniform(0.1, 1e3, u)  # badly scaled columns
    if cond is not None:  # mix the columns to a given condition of the scaled design
        U, _, Vt = np.linalg.svd(rng.normal(size=(m, u)), full_matrices=False)
        A = (U * np.geomspace(1.0, 1.0 / cond, u)) @ Vt * rng.uniform(0.1, 1e3, u)
    x = rng.normal(size=u)
    L = A @ x + rng.normal(scale=0.1, size=m)
    return A, L


def _reference(A, L, w):
    """Weighted least squares and its statistics by explicit formulas (small dense)."""
    N = A.T @ (w[:, None] * A)
    Q = np.linalg.inv(N)
    x = Q @ (A.T @ (w * L))
    v = A @ x - L
    Qvv = np.diag(1 / w) - A @ Q @ A.T
    red = np.diag(Qvv) * w
    nres = w * v / np.sqrt(np.diag(np.diag(w) @ Qvv @ np.diag(w)))
    return x, Q, v, red, nres


@pytest.mark.parametrize("weighted", [False, True])
def test_normal_equation_path_equals_qr_and_formulas(monkeypatch, weighted):
    A, L = _tall(m=700)
    w = np.random.default_rng(3).uniform(0.2, 5.0, L.size) if weighted else np.ones(L.size)
    kw = {"weights": w} if weighted else {}
    qr = solve_linear(A, L, **kw)
    monkeypatch.setattr(gm, "NORMAL_FROM", 0)  # the normal equations for this size too
    ne = solve_linear(A, L, **kw)
    x, Q, v, red, nres = _reference(A, L, w)
    for adj in (qr, ne):
        np.testing.assert_allclose(adj.x, x, rtol=1e-11)
        np.testing.assert_allclose(adj.cofactor, Q, rtol=1e-9, atol=1e-14 * np.abs(Q).max())
        np.testing.assert_allclose(adj.residuals, v, atol=1e-9)
        np.testing.assert_allclose(adj.redundancy_numbers, red, atol=1e-10)
        np.testing.assert_allclose(adj.normalized_residuals, nres, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(ne.x, qr.x, rtol=1e-12)


def test_ill_conditioned_tall_design_falls_back_to_qr(monkeypatch):
    """Above the condition limit of the normal equations the blocked QR decides, and gives
    the QR answer (no digits lost to the squared condition)."""
    A, L = _tall(m=9000, cond=1e7, seed=1)
    calls = []
    real = gm._qr_factor
    monkeypatch.setattr(gm, "_qr_factor", lambda *a: calls.append(1) or real(*a))
    monkeypatch.setattr(gm, "NORMAL_FROM", 0)
    adj = solve_linear(A, L)
    assert calls, "the QR path was not taken"
    monkeypatch.setattr(gm, "NORMAL_FROM", 10**9)
    ref = solve_linear(A, L)
    np.testing.assert_allclose(adj.x, ref.x, rtol=1e-9)


def test_blocked_qr_equals_householder_r():
    rng = np.random.default_rng(5)
    M = rng.normal(size=(20000, 7))
    R1 = gm._tsqr(M)[:7]
    R2 = np.linalg.qr(M, mode="r")
    signs = np.sign(np.diag(R1)) * np.sign(np.diag(R2))
    np.testing.assert_allclose(R1 * signs[:, None], R2, rtol=1e-10, atol=1e-10)
    R3 = gm.r_factor(M)
    np.testing.assert_allclose(np.abs(R3), np.abs(R2), rtol=1e-10, atol=1e-10)
    assert np.all(np.tril(R3, -1) == 0)


@pytest.mark.parametrize("log_cond", [6.0, 11.5, 11.9, 12.1, 13.0])
def test_condition_certificate_agrees_with_the_svd_rule(log_cond):
    """The Frobenius bound only skips the SVD when it proves the check; the decision is the
    SVD rule's (reciprocal condition <= 1e-12 raises)."""
    rng = np.random.default_rng(int(log_cond * 10))
    U, _ = np.linalg.qr(rng.normal(size=(8, 8)))
    V, _ = np.linalg.qr(rng.normal(size=(8, 8)))
    s = np.geomspace(1.0, 10.0**-log_cond, 8)
    R = np.linalg.qr((U * s) @ V.T, mode="r")
    names = tuple("abcdefgh")
    sv = np.linalg.svd(R, compute_uv=False)
    if sv[-1] <= gm.RCOND_LIMIT * sv[0]:
        with pytest.raises(DegenerateGeometryError, match="undetermined"):
            gm._inverse_checked(R, names, "test")
    else:
        Rinv = gm._inverse_checked(R, names, "test")
        np.testing.assert_allclose(Rinv @ R, np.eye(8), atol=1e-3)


def test_rank_deficient_tall_design_names_the_parameters(monkeypatch):
    A, L = _tall(m=5000, u=4)
    A = np.column_stack([A, A[:, 1] * 3.0])
    monkeypatch.setattr(gm, "NORMAL_FROM", 0)
    with pytest.raises(DegenerateGeometryError, match=r"b, e"):
        solve_linear(A, L, names="abcde")
    with pytest.raises(DegenerateGeometryError, match="no observation depends on c"):
        solve_linear(np.column_stack([A[:, :2], 0 * A[:, 0]]), L, names="abc")


def test_statistics_false_same_estimate():
    A, L = _tall(m=300)
    full = solve_linear(A, L)
    bare = solve_linear(A, L, statistics=False)
    np.testing.assert_array_equal(bare.x, full.x)
    assert bare.residuals.size == 0 and np.all(np.isnan(bare.cofactor))
    assert np.isnan(bare.vtpv) and np.isnan(bare.sigma0)
    assert bare.redundancy == full.redundancy

    t = np.linspace(0, 4, 30)
    y = 3.0 * np.exp(-0.8 * t) + 0.5 + np.random.default_rng(7).normal(scale=0.02, size=30)

    def f(p):
        return p[0] * np.exp(-p[1] * t) + p[2]

    def jac(p):
        e = np.exp(-p[1] * t)
        return np.column_stack([e, -p[0] * t * e, np.ones_like(t)])

    full = gauss_markov(f, [2.0, 0.5, 0.0], y, jacobian=jac)
    bare = gauss_markov(f, [2.0, 0.5, 0.0], y, jacobian=jac, statistics=False)
    np.testing.assert_array_equal(bare.x, full.x)
    assert bare.iterations == full.iterations and bare.converged
    assert bare.residuals.size == 0 and np.all(np.isnan(bare.cofactor))


def test_step_control_reuses_the_trial_evaluation():
    """One model evaluation per iteration (the step-control trial is the next iteration's
    model), none for the converged step, one for the statistics."""
    t = np.linspace(0, 4, 30)
    y = 3.0 * np.exp(-0.8 * t) + 0.5 + np.random.default_rng(8).normal(scale=0.02, size=30)
    calls = []

    def f(p):
        calls.append(1)
        return p[0] * np.exp(-p[1] * t) + p[2]

    def jac(p):
        e = np.exp(-p[1] * t)
        return np.column_stack([e, -p[0] * t * e, np.ones_like(t)])

    adj = gauss_markov(f, [2.0, 0.5, 0.0], y, jacobian=jac)
    assert adj.converged
    assert len(calls) == adj.iterations + 1
    calls.clear()
    bare = gauss_markov(f, [2.0, 0.5, 0.0], y, jacobian=jac, statistics=False)
    assert len(calls) == bare.iterations
