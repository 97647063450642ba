"""Gauss-Newton iteration of the rational projective equations for small, unit-weight problems.

The estimate of ``estimate_transform(..., "projective2d" / "projective3d",
statistics=False)`` without weights or covariances: the same iteration as
:func:`photogeom.adjust.gauss_markov` (same start, same steps up to rounding, same
convergence rule: the step changes the computed target coordinates by at most
``tol * (1 + rms(v)) + 64 eps max|L|``), written for this one model so that a small problem
costs a few dozen numpy calls instead of the general engine's few hundred.

The step solves the normal equations ``J.T J dx = -J.T v`` by Cholesky. Their rounding
changes the path, not the solution: the iteration stops where the gradient ``J.T v`` vanishes,
which is computed from the residuals themselves. Whenever this path cannot vouch for its
answer (a Cholesky failure, a poorly conditioned step, a step that increases ``v.T v``, the
iteration limit), it returns None and the caller runs the general engine, which repeats the
iteration with step control and reports the problem with its diagnostics.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg.lapack as _lapack

_EPS = float(np.finfo(float).eps)

#: Largest accepted condition of the normal equations (LAPACK's estimate from the Cholesky
#: factor): their solution then carries at least about four significant digits per step.
COND_LIMIT = 1e12


def gauss_newton_unit(
    u: np.ndarray, X: np.ndarray, p0: np.ndarray, max_iter: int, tol: float
) -> tuple[np.ndarray, int] | None:
    """Least-squares rational projective map of points ``u`` (n, d) to ``X`` (n, d).

    Parameters
    ----------
    u : numpy.ndarray, shape (n, d)
        Source points (normalised: centred and scaled to unit RMS).
    X : numpy.ndarray, shape (n, d)
        Target points (centred), in target units.
    p0 : numpy.ndarray, shape ((d + 1)^2 - 1,)
        Start: the row-major elements of ``H`` with ``H[d, d] = 1`` left out.
    max_iter : int
        Iteration limit.
    tol : float
        Convergence tolerance (as :func:`photogeom.adjust.gauss_markov`).

    Returns
    -------
    (p, iterations) or None
        The estimate and the number of iterations (each with a Jacobian and a step, the last
        one's step within the tolerance), or None when the general engine must decide.
    """
    n, d = u.shape
    m = d + 1
    npar = m * m - 1
    floor = 64 * _EPS * float(np.abs(X).max())
    u1 = np.empty((n, m))
    u1[:, :d] = u
    u1[:, d] = 1.0
    h_flat = np.empty(m * m)
    h_flat[:-1] = p0
    h_flat[-1] = 1.0
    H = h_flat.reshape(m, m)  # a view: updates of h_flat[:-1] update H
    J = np.zeros((n, d, npar))
    Jm = J.reshape(n * d, npar)
    last = J[:, :, d * m:]
    v, w, Hx, cost = _residuals(u1, H, X)
    for it in range(1, max_iter + 1):
        if not math.isfinite(cost):
            return None
        limit = tol * (1.0 + math.sqrt(cost / (n * d))) + floor
        a = u1 / w[:, None]  # d X_k / d H[k] = [u, 1] / w
        for k in range(d):
            J[:, k, k * m:(k + 1) * m] = a
        np.multiply(Hx[:, :, None], a[:, None, :d], out=last)  # d X_k / d H[d, :d] = -X_k u / w
        np.negative(last, out=last)
        N = Jm.T @ Jm
        c, dx, info = _lapack.dposv(N, Jm.T @ v)  # dx = -step
        if info != 0:
            return None
        step = float(np.abs(Jm @ dx).max())
        h_flat[:-1] -= dx
        if step <= limit:
            # the engine's rank check at the solution: a reciprocal condition estimate of N
            # from its Cholesky factor (1-norm bounded by sqrt(npar) |N|_F: errs towards
            # "poorly conditioned"); intermediate steps are guarded by the decrease of v.T v
            rcond, info = _lapack.dpocon(c, math.sqrt(npar * float(np.vdot(N, N))))
            if info != 0 or not rcond * COND_LIMIT > 1.0:
                return None
            return h_flat[:-1].copy(), it
        # the step must not increase v.T v (the engine would halve it: let it decide)
        v, w, Hx, cost_new = _residuals(u1, H, X)
        if not (math.isfinite(cost_new) and cost_new <= cost * (1 + 1e-12)):
            return None
        cost = cost_new
    return None


def _residuals(u1: np.ndarray, H: np.ndarray, X: np.ndarray):
    """Residuals (flat), denominators, mapped points and ``v.T v`` of the map ``H``."""
    h = u1 @ H.T
    d = X.shape[1]
    w = h[:, d]
    Hx = h[:, :d] / w[:, None]
    v = (Hx - X).reshape(-1)
    return v, w, Hx, float(v @ v)
