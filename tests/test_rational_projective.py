"""The rational form of the projective models: its Jacobian against central differences, and
the small-problem Gauss-Newton path against the general engine.

``gauss_newton_unit`` (normal equations, Cholesky) must give the estimate of
``gauss_markov`` on the rational model (QR of the design, step control), or None so that the
engine decides; and it must recover noise-free homographies of any kind.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom.adjust import gauss_markov
from photogeom.estimation.rational_projective import (
    gauss_newton_unit,
    homogeneous_matrix,
    homogeneous_points,
    rational_jacobian,
    rational_map,
)


def _homography(rng: np.random.Generator, d: int, perspective: float) -> np.ndarray:
    m = d + 1
    H = np.eye(m)
    H[:d, :d] = rng.normal(size=(d, d)) + 2.0 * np.eye(d)
    H[:d, d] = rng.normal(size=d)
    H[d, :d] = perspective * rng.normal(size=d)
    return H


def _map(H: np.ndarray, u: np.ndarray) -> np.ndarray:
    d = u.shape[1]
    h = u @ H[:, :d].T + H[:, d]
    return h[:, :d] / h[:, d:]


def _engine(u, X, p0, tol=1e-10):
    d = u.shape[1]
    m = d + 1

    def model(p):
        return _map(np.append(p, 1.0).reshape(m, m), u).reshape(-1)

    def jac(p):
        H = np.append(p, 1.0).reshape(m, m)
        w = u @ H[d, :d] + 1.0
        Xh = _map(H, u)
        a = np.column_stack([u, np.ones(len(u))]) / w[:, None]
        J = np.zeros((len(u), d, m * m - 1))
        for k in range(d):
            J[:, k, k * m:(k + 1) * m] = a
            J[:, k, d * m:] = -Xh[:, k:k + 1] * a[:, :d]
        return J.reshape(len(u) * d, -1)

    return gauss_markov(model, p0, X.reshape(-1), jacobian=jac, tol=tol, statistics=False)


def _problem(seed: int, d: int, n: int, noise: float, perspective: float):
    rng = np.random.default_rng(seed)
    H = _homography(rng, d, perspective)
    u = rng.uniform(-1.5, 1.5, (n, d))
    X = _map(H, u)
    X = X - X.mean(axis=0)
    H_centred = H.copy()
    H_centred[:d] -= np.outer(_map(H, u).mean(axis=0), H[d])
    # start: the true map with a small error (as the linearised start provides)
    p_true = (H_centred / H_centred[d, d]).reshape(-1)[:-1]
    p0 = p_true * (1.0 + 1e-3 * rng.normal(size=p_true.size))
    return u, X + noise * rng.normal(size=X.shape), p_true, p0


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    d=st.sampled_from([2, 3]),
    extra=st.integers(2, 40),
    noise=st.sampled_from([1e-4, 1e-2]),
    perspective=st.floats(0.0, 0.25),
)
def test_same_estimate_as_the_engine(seed, d, extra, noise, perspective):
    n = (d + 1) ** 2 // d + extra
    u, X, _, p0 = _problem(seed, d, n, noise, perspective)
    try:
        ref = _engine(u, X, p0)
    except Exception:  # the engine refuses (degenerate draw): the lean path must not answer
        assert gauss_newton_unit(u, X, p0, 50, 1e-10) is None
        return
    out = gauss_newton_unit(u, X, p0, 50, 1e-10)
    if out is None:  # allowed: the engine decides (it was just run)
        return
    p, iterations = out
    scale = np.max(np.abs(ref.x))
    assert np.max(np.abs(p - ref.x)) <= 1e-9 * scale
    assert abs(iterations - ref.iterations) <= 1


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    d=st.sampled_from([2, 3]),
    perspective=st.floats(0.0, 0.3),
)
def test_noise_free_recovery(seed, d, perspective):
    n = 3 * (d + 1) ** 2
    u, X, p_true, p0 = _problem(seed, d, n, 0.0, perspective)
    out = gauss_newton_unit(u, X, p0, 50, 1e-10)
    assert out is not None
    np.testing.assert_allclose(out[0], p_true, rtol=0, atol=1e-8 * np.max(np.abs(p_true)))


def test_hands_over_when_it_cannot_vouch():
    u, X, _, p0 = _problem(1, 2, 20, 1e-2, 0.1)
    # iteration limit: the engine reports it
    assert gauss_newton_unit(u, X, p0, 1, 1e-10) is None
    # collinear source points: the normal equations are singular
    t = np.linspace(-1, 1, 20)
    line = np.column_stack([t, 0.5 * t])
    assert gauss_newton_unit(line, X, p0, 50, 1e-10) is None
    # a start whose first step increases v.T v (the engine halves steps, this path does not)
    bad = p0.copy()
    bad[6:] = [3.0, -3.0]  # the horizon runs through the points
    out = gauss_newton_unit(u, X, bad, 50, 1e-10)
    assert out is None or np.allclose(out[0], _engine(u, X, p0).x, atol=1e-8)


@pytest.mark.parametrize("d", [2, 3])
def test_public_fit_uses_it_and_agrees_with_statistics(d):
    """estimate_transform(..., statistics=False) = the adjustment with statistics."""
    import photogeom as pg

    rng = np.random.default_rng(5)
    H = _homography(rng, d, 0.05)
    src = rng.uniform(0, 100, (25, d))
    dst = _map(H, src / 50.0) * 30.0 + rng.normal(0, 0.01, (25, d))
    model = f"projective{d}d"
    full = pg.estimate_transform(model, src, dst)
    bare = pg.estimate_transform(model, src, dst, statistics=False)
    np.testing.assert_allclose(bare.parameters, full.parameters, rtol=1e-11, atol=1e-14)
    assert bare.iterations == full.iterations and bare.converged


@pytest.mark.parametrize("d, n", [(2, 7), (3, 9), (2, 5000), (3, 4500)])
def test_jacobian_against_central_differences(d, n):
    """Both ways of building the Jacobian (blocks for few points, columns for many) against
    central differences of the map."""
    rng = np.random.default_rng(d * n)
    H = _homography(rng, d, 0.1)
    u = rng.uniform(-1.5, 1.5, (n, d))
    p = (H / H[d, d]).reshape(-1)[:-1]
    u1 = homogeneous_points(u)
    X, w = rational_map(homogeneous_matrix(p, d), u1)
    J = rational_jacobian(u1, X, w)
    num = np.empty_like(J)
    for j in range(p.size):
        e = np.zeros(p.size)
        e[j] = 1e-6
        plus = rational_map(homogeneous_matrix(p + e, d), u1)[0].reshape(-1)
        minus = rational_map(homogeneous_matrix(p - e, d), u1)[0].reshape(-1)
        num[:, j] = (plus - minus) / 2e-6
    np.testing.assert_allclose(J, num, rtol=0, atol=1e-6 * np.abs(num).max())
    # the rational map itself: homogeneous coordinates divided by their last element
    h = np.column_stack([u, np.ones(n)]) @ (H / H[d, d]).T
    np.testing.assert_allclose(X, h[:, :d] / h[:, d:], rtol=1e-13, atol=1e-13)
