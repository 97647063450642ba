"""The least-squares engine against independent formulas, scipy, and Monte Carlo."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.optimize
import scipy.sparse

from photogeom.adjust import (
    Fit,
    data_snooping,
    gauss_helmert,
    gauss_markov,
    normalize_points,
    ransac,
    solve_linear,
)
from photogeom.adjust.snooping import tau_critical_value
from photogeom.errors import ConvergenceError, DegenerateGeometryError, InputError


@pytest.fixture
def line_problem():
    rng = np.random.default_rng(42)
    t = np.linspace(-3, 5, 40)
    A = np.column_stack([np.ones_like(t), t, t**2])
    x_true = np.array([1.5, -0.7, 0.2])
    L = A @ x_true + rng.normal(scale=0.05, size=t.size)
    return A, L


def test_linear_matches_weighted_normal_equations(line_problem):
    A, L = line_problem
    w = np.linspace(0.5, 3.0, L.size)
    adj = solve_linear(A, L, weights=w, names=["a", "b", "c"])
    N = A.T @ (w[:, None] * A)
    x = np.linalg.solve(N, A.T @ (w * L))
    np.testing.assert_allclose(adj.x, x, rtol=1e-12)
    np.testing.assert_allclose(adj.cofactor, np.linalg.inv(N), rtol=1e-10)
    v = A @ x - L  # computed minus observed
    np.testing.assert_allclose(adj.residuals, v, atol=1e-12)
    r = L.size - 3
    assert adj.redundancy == r
    assert adj.sigma0 == pytest.approx(np.sqrt(v @ (w * v) / r), rel=1e-12)
    np.testing.assert_allclose(adj.std, adj.sigma0 * np.sqrt(np.diag(np.linalg.inv(N))), rtol=1e-10)
    assert adj.redundancy_numbers.sum() == pytest.approx(r)
    # Baarda: w_i = v_i / (sigma0_prior * sqrt(qvv_ii)), Qvv = P^-1 - A Qxx A.T
    Qvv = np.diag(1 / w) - A @ np.linalg.inv(N) @ A.T
    np.testing.assert_allclose(
        np.abs(adj.normalized_residuals), np.abs(v / np.sqrt(np.diag(Qvv))), rtol=1e-8
    )


def test_correlated_observations_match_gls_formula(line_problem):
    A, L = line_problem
    n = L.size
    rng = np.random.default_rng(1)
    B = rng.normal(size=(n, n)) * 0.05
    C = 0.01 * (B @ B.T + np.eye(n))
    adj = solve_linear(A, L, covariance=C, sigma0_prior=0.1)
    P = 0.01 * np.linalg.inv(C)
    N = A.T @ P @ A
    x = np.linalg.solve(N, A.T @ P @ L)
    np.testing.assert_allclose(adj.x, x, rtol=1e-10)
    np.testing.assert_allclose(adj.cofactor, np.linalg.inv(N), rtol=1e-8)
    v = A @ x - L
    assert adj.vtpv == pytest.approx(v @ P @ v, rel=1e-10)
    Qvv = np.linalg.inv(P) - A @ np.linalg.inv(N) @ A.T
    PQP = P @ Qvv @ P
    w_expected = (P @ v) / (0.1 * np.sqrt(np.diag(PQP)))
    np.testing.assert_allclose(adj.normalized_residuals, w_expected, rtol=1e-7)
    np.testing.assert_allclose(adj.redundancy_numbers, np.diag(Qvv @ P), atol=1e-10)


def test_block_covariance_equals_full(line_problem):
    A, L = line_problem
    rng = np.random.default_rng(5)
    blocks = np.empty((20, 2, 2))
    for i in range(20):
        m = rng.normal(size=(2, 2))
        blocks[i] = m @ m.T + 0.5 * np.eye(2)
    full = np.zeros((40, 40))
    for i in range(20):
        full[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = blocks[i]
    a = solve_linear(A, L, covariance=blocks)
    b = solve_linear(A, L, covariance=full)
    np.testing.assert_allclose(a.x, b.x, rtol=1e-12)
    np.testing.assert_allclose(a.cofactor, b.cofactor, rtol=1e-10)
    np.testing.assert_allclose(a.normalized_residuals, b.normalized_residuals, rtol=1e-9)


def test_redundancy_zero_sigma0_undefined():
    A = np.array([[1.0, 0.0], [0.0, 1.0]])
    adj = solve_linear(A, [1.0, 2.0])
    assert adj.redundancy == 0
    assert np.isnan(adj.sigma0)
    assert np.all(np.isnan(adj.covariance))
    np.testing.assert_allclose(adj.covariance_prior, np.eye(2))


def test_rank_deficiency_names_parameters():
    t = np.linspace(0, 1, 10)
    A = np.column_stack([t, 2 * t, np.ones_like(t)])
    with pytest.raises(DegenerateGeometryError, match=r"a, b"):
        solve_linear(A, t, names=["a", "b", "c"])
    with pytest.raises(DegenerateGeometryError, match="no observation depends on c"):
        solve_linear(np.column_stack([t, np.ones_like(t), 0 * t]), t, names="abc")


def test_bad_inputs():
    with pytest.raises(InputError, match="NaN"):
        solve_linear(np.ones((3, 1)), [1.0, np.nan, 2.0])
    with pytest.raises(InputError, match="observation"):
        solve_linear(np.ones((3, 2)), [1.0, 2.0])
    with pytest.raises(InputError, match="> 0"):
        solve_linear(np.ones((3, 1)), [1.0, 2.0, 3.0], weights=[1, 0, 1])
    with pytest.raises(InputError, match="positive definite"):
        solve_linear(np.ones((2, 1)), [1.0, 2.0], covariance=[[1, 2], [2, 1]])


def test_constraints_match_bordered_normal_equations(line_problem):
    A, L = line_problem
    H = np.array([[1.0, 1.0, 1.0]])
    h = np.array([1.0])
    adj = solve_linear(A, L, constraints=(H, h))
    N = A.T @ A
    K = np.block([[N, H.T], [H, np.zeros((1, 1))]])
    sol = np.linalg.solve(K, np.concatenate([A.T @ L, h]))
    np.testing.assert_allclose(adj.x, sol[:3], rtol=1e-10)
    np.testing.assert_allclose(adj.cofactor, np.linalg.inv(K)[:3, :3], atol=1e-12)
    assert adj.redundancy == L.size - 3 + 1
    nl = gauss_markov(
        lambda x: A @ x,
        np.zeros(3),
        L,
        jacobian=lambda x: A,
        constraints=(lambda x: H @ x - h, lambda x: H),
    )
    np.testing.assert_allclose(nl.x, adj.x, rtol=1e-9)


def test_nonlinear_matches_scipy_least_squares():
    rng = np.random.default_rng(7)
    t = np.linspace(0, 4, 30)
    y = 3.0 * np.exp(-0.8 * t) + 0.5 + rng.normal(scale=0.02, size=t.size)

    def f(p):
        return p[0] * np.exp(-p[1] * t) + p[2]

    def J(p):
        e = np.exp(-p[1] * t)
        return np.column_stack([e, -p[0] * t * e, np.ones_like(t)])

    adj = gauss_markov(f, [1.0, 0.3, 0.0], y, jacobian=J, names=["a", "k", "c"])
    ref = scipy.optimize.least_squares(lambda p: f(p) - y, [1.0, 0.3, 0.0], xtol=1e-15, ftol=1e-15)
    np.testing.assert_allclose(adj.x, ref.x, rtol=1e-8)
    assert adj.converged and adj.iterations < 20
    num = gauss_markov(f, [1.0, 0.3, 0.0], y)  # numerical Jacobian
    np.testing.assert_allclose(num.x, adj.x, rtol=1e-7)
    np.testing.assert_allclose(num.std, adj.std, rtol=1e-4)


def test_nonconvergence_is_reported():
    t = np.linspace(0, 4, 30)
    y = 3.0 * np.exp(-0.8 * t)

    def f(p):
        return p[0] * np.exp(-p[1] * t)

    with pytest.raises(ConvergenceError, match="iteration limit 2"):
        gauss_markov(f, [1.0, 0.0], y, max_iter=2)
    adj = gauss_markov(f, [1.0, 0.0], y, max_iter=2, raise_on_failure=False)
    assert not adj.converged and "iteration limit" in adj.message


def test_linear_std_matches_monte_carlo():
    rng = np.random.default_rng(11)
    t = np.linspace(-1, 1, 15)
    A = np.column_stack([np.ones_like(t), t, t**2])
    sigma = np.linspace(0.5, 2.0, t.size)
    w = 1 / sigma**2
    ref = solve_linear(A, A @ [1.0, 2.0, 3.0], weights=w)
    trials = 2000
    noise = rng.normal(size=(trials, t.size)) * sigma
    Ls = (A @ [1.0, 2.0, 3.0])[None, :] + noise
    xs = np.array([solve_linear(A, L, weights=w).x for L in Ls[:600]])
    xs_fast = (np.linalg.solve(A.T @ (w[:, None] * A), (A.T * w) @ Ls.T)).T
    np.testing.assert_allclose(xs, xs_fast[:600], rtol=1e-9)
    emp = xs_fast.std(axis=0, ddof=1)
    np.testing.assert_allclose(
        emp,
        ref.std_prior if hasattr(ref, "std_prior") else np.sqrt(np.diag(ref.covariance_prior)),
        rtol=0.1,
    )
    # a-posteriori sigma0 is unbiased: mean of sigma0^2 ~ 1
    s0 = np.array([solve_linear(A, L, weights=w).sigma0 for L in Ls[:400]])
    assert np.mean(s0**2) == pytest.approx(1.0, rel=0.1)


def _line_gh(L, sparse=False):
    def g(p, l):
        l = l.reshape(-1, 2)
        return l[:, 1] - p[0] * l[:, 0] - p[1]

    def gx(p, l):
        l = l.reshape(-1, 2)
        return np.column_stack([-l[:, 0], -np.ones(len(l))])

    def gl(p, l):
        n = len(l) // 2
        B = scipy.sparse.lil_matrix((n, 2 * n))
        B[np.arange(n), 2 * np.arange(n)] = -p[0]
        B[np.arange(n), 2 * np.arange(n) + 1] = 1.0
        return B.tocsr() if sparse else B.toarray()

    return gauss_helmert(g, [1.0, 0.0], L, jacobian_x=gx, jacobian_l=gl, names=["m", "b"])


def test_gauss_helmert_line_equals_orthogonal_regression():
    rng = np.random.default_rng(2)
    x = np.linspace(0, 10, 25)
    xo = x + rng.normal(scale=0.1, size=x.size)
    yo = 2 * x + 1 + rng.normal(scale=0.1, size=x.size)
    adj = _line_gh(np.column_stack([xo, yo]).ravel())
    # independent: total least squares via the SVD of the centred data
    c = np.array([xo.mean(), yo.mean()])
    _, _, Vt = np.linalg.svd(np.column_stack([xo, yo]) - c)
    nvec = Vt[-1]
    m = -nvec[0] / nvec[1]
    np.testing.assert_allclose(adj.x, [m, c[1] - m * c[0]], rtol=1e-9)
    corrected = adj.corrected_observations.reshape(-1, 2)
    np.testing.assert_allclose(corrected[:, 1], m * corrected[:, 0] + adj.x[1], atol=1e-9)
    assert adj.redundancy == x.size - 2
    assert adj.redundancy_numbers.sum() == pytest.approx(adj.redundancy, rel=1e-6)


def test_gauss_helmert_sparse_path_equals_dense(monkeypatch):
    import importlib

    gh = importlib.import_module("photogeom.adjust.gauss_helmert")

    rng = np.random.default_rng(4)
    x = np.linspace(0, 10, 40)
    L = np.column_stack(
        [x + rng.normal(scale=0.1, size=40), 2 * x + rng.normal(scale=0.1, size=40)]
    ).ravel()
    dense = _line_gh(L)
    monkeypatch.setattr(gh, "DENSE_LIMIT", 5)
    sparse = _line_gh(L, sparse=True)
    np.testing.assert_allclose(sparse.x, dense.x, rtol=1e-10)
    np.testing.assert_allclose(sparse.std, dense.std, rtol=1e-8)
    assert sparse.sigma0 == pytest.approx(dense.sigma0, rel=1e-9)


def test_gauss_helmert_std_matches_monte_carlo():
    rng = np.random.default_rng(9)
    x = np.linspace(0, 10, 12)
    truth = np.column_stack([x, 0.5 * x + 1]).ravel()
    est = []
    stds = []
    for _ in range(400):
        adj = _line_gh(truth + rng.normal(scale=0.1, size=truth.size))
        est.append(adj.x)
        stds.append(np.sqrt(np.diag(adj.covariance_prior)))
    emp = np.std(est, axis=0, ddof=1)
    np.testing.assert_allclose(emp, 0.1 * np.mean(stds, axis=0), rtol=0.1)


def test_data_snooping_finds_planted_blunder(line_problem):
    A, L = line_problem
    L = L.copy()
    L[17] += 1.0  # 20 sigma
    adj = solve_linear(A, L, weights=np.full(L.size, 1 / 0.05**2))
    res = data_snooping(adj)
    assert res.critical_value == pytest.approx(3.2905, abs=1e-4)
    assert res.suspect == 17
    tau = data_snooping(adj, sigma="posterior")
    assert tau.test == "tau" and tau.suspect == 17
    assert tau.critical_value == pytest.approx(tau_critical_value(0.001, adj.redundancy))
    # without the blunder nothing is flagged at this level with correct weights
    A2, L2 = A, L.copy()
    L2[17] -= 1.0
    assert data_snooping(solve_linear(A2, L2, weights=np.full(L.size, 400.0))).suspect is None


def test_tau_critical_value_limits():
    # tau critical -> normal critical for large r; <= sqrt(r) always
    from scipy import stats

    assert tau_critical_value(0.001, 10**6) == pytest.approx(stats.norm.ppf(1 - 0.0005), rel=1e-4)
    assert tau_critical_value(0.05, 3) < np.sqrt(3)


def test_ransac_line_with_outliers():
    rng = np.random.default_rng(0)
    n = 300
    x = rng.uniform(0, 10, n)
    y = 0.5 * x - 2 + rng.normal(scale=0.01, size=n)
    bad = rng.random(n) < 0.4
    y[bad] = rng.uniform(-10, 10, bad.sum())

    def solve(s):
        x1, x2, y1, y2 = x[s[:, 0]], x[s[:, 1]], y[s[:, 0]], y[s[:, 1]]
        valid = np.abs(x2 - x1) > 1e-9
        m = np.where(valid, (y2 - y1) / np.where(valid, x2 - x1, 1), 0)
        return np.column_stack([m, y1 - m * x1]), valid

    def errors(models):
        return np.abs(models[:, :1] * x[None] + models[:, 1:] - y[None])

    res = ransac(n, 2, solve, errors, threshold=0.05, rng=1)
    assert res.model[0] == pytest.approx(0.5, abs=0.01)
    assert np.all(res.inliers[~bad])  # every good point is an inlier
    true_dist = np.abs(0.5 * x - 2 - y)
    # wrong points are inliers only where they happen to lie on the line
    assert np.all(true_dist[res.inliers & bad] < 0.06)
    assert res.trials < 10000  # the adaptive stop worked


def test_normalization_round_trip():
    p = np.array([[4e6, 5e5], [4e6 + 10, 5e5 - 3], [4e6 - 7, 5e5 + 1]])
    norm = normalize_points(p)
    q = norm.apply(p)
    np.testing.assert_allclose(q.mean(axis=0), 0, atol=1e-9)
    np.testing.assert_allclose(np.sqrt(np.mean(np.sum(q**2, axis=1)) / 2), 1.0)
    np.testing.assert_allclose(norm.undo(q), p, rtol=1e-15)
    h = np.column_stack([p, np.ones(3)]) @ norm.matrix.T
    np.testing.assert_allclose(h[:, :2], q, atol=1e-9)


def test_fit_reporting(line_problem):
    A, L = line_problem
    adj = solve_linear(A, L, names=["a0", "a1", "a2"])
    fit = Fit.from_adjustment(
        adj,
        model=None,
        method="linear least squares",
        point_dim=2,
        residual_labels=("x", "y"),
        residual_unit="m",
        parameter_units={"a0": "m", "a1": "1", "a2": "rad"},
    )
    v = adj.residuals.reshape(-1, 2)
    assert fit.rmse == pytest.approx(np.sqrt(np.sum(v**2) / v.shape[0]))
    np.testing.assert_allclose(fit.rms_per_axis, np.sqrt(np.mean(v**2, axis=0)))
    assert set(fit.std_errors) == {"a0", "a1", "a2"}
    text = fit.summary()
    assert "computed - observed" in text and "deg" in text and "RMSE" in text
    fit2 = fit.with_checks(np.array([[0.1, -0.2]]), ["c1"])
    assert fit2.check_rmse == pytest.approx(np.hypot(0.1, 0.2))
    d = fit2.to_dict()
    json.dumps(d)
    assert d["residual_convention"] == "computed minus observed"
    assert fit.snooping().critical_value == pytest.approx(3.2905, abs=1e-4)
    # r = 0: sigma0 undefined, not a crash
    fit0 = Fit.from_adjustment(solve_linear(np.eye(2), [1.0, 2.0]), None, "x", point_dim=2)
    assert "undefined" in fit0.summary()
    assert json.loads(json.dumps(fit0.to_dict()))["sigma0"] is None
