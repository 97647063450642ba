"""The rational form of the projective models: ``X = (H [u, 1])[:d] / (H [u, 1])[d]``.

The map and its Jacobian in the parameters (the row-major elements of ``H`` with
``H[d, d] = 1`` left out) serve the general adjustment engine (:class:`RationalModel`) and
a Gauss-Newton iteration for small unit-weight problems (:func:`gauss_newton_unit`).

:func:`gauss_newton_unit` is the estimate of ``estimate_transform(..., "projective2d" /
"projective3d", statistics=False)`` without weights or covariances: the same iteration as
:func:`photogeom.adjust.gauss_markov` (same start, same steps up to rounding, same
convergence rule: the step changes the computed target coordinates by at most
``tol * (1 + rms(v)) + 64 eps max|L|``), written for this one model so that a small problem
costs a few dozen numpy calls instead of the general engine's few hundred. The step solves
the normal equations ``J.T J dx = -J.T v`` by Cholesky. Their rounding changes the path, not
the solution: the iteration stops where the gradient ``J.T v`` vanishes, which is computed
from the residuals themselves. Whenever this path cannot vouch for its answer (a Cholesky
failure, a poorly conditioned step, a step that increases ``v.T v``, the iteration limit), it
returns None and the caller runs the general engine, which repeats the iteration with step
control and reports the problem with its diagnostics.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg.lapack as _lapack

_EPS = float(np.finfo(float).eps)

#: Largest accepted condition of the normal equations (LAPACK's estimate from the Cholesky
#: factor): their solution then carries at least about four significant digits per step.
COND_LIMIT = 1e12


def affine_rows(M: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``[u, 1] @ M.T`` for points u (n, d) and M (k, d + 1)."""
    d = u.shape[1]
    return u @ M[:, :d].T + M[:, d]


def homogeneous_matrix(p: np.ndarray, d: int) -> np.ndarray:
    """The (d+1, d+1) matrix of the (d+1)^2 - 1 parameters, last element 1."""
    H = np.empty((d + 1) * (d + 1))
    H[:-1] = p
    H[-1] = 1.0
    return H.reshape(d + 1, d + 1)


def homogeneous_points(u: np.ndarray) -> np.ndarray:
    """``[u, 1]`` (n, d + 1) of points u (n, d)."""
    n, d = u.shape
    u1 = np.empty((n, d + 1))
    u1[:, :d] = u
    u1[:, d] = 1.0
    return u1


def rational_map(H: np.ndarray, u1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The map ``H`` ((d+1, d+1)) of points given as ``u1 = [u, 1]`` (n, d + 1): mapped
    points (n, d) and their denominators ``w`` (n,)."""
    d = u1.shape[1] - 1
    h = u1 @ H.T
    w = h[:, d]
    return h[:, :d] / w[:, None], w


def rational_jacobian(
    u1: np.ndarray, X: np.ndarray, w: np.ndarray, out: np.ndarray | None = None
) -> np.ndarray:
    """d X / d p of the map at points ``u1 = [u, 1]`` (``X``, ``w``: mapped points and
    denominators there), rows point by point: (n d, (d+1)^2 - 1).

    Few points (up to 4096): built by blocks (fewest calls), into ``out`` ((n, d, npar),
    zero outside the blocks, e.g. a previous result) when given; many: column by column
    (Fortran order: contiguous writes)."""
    n, m = u1.shape
    d = m - 1
    npar = m * m - 1
    a = u1 / w[:, None]  # d X_k / d H[k] = [u, 1] / w
    if n <= 4096:
        J = np.zeros((n, d, npar)) if out is None else out
        for k in range(d):
            J[:, k, k * m:(k + 1) * m] = a
        last = J[:, :, d * m:]
        np.multiply(X[:, :, None], a[:, None, :d], out=last)  # d X_k / d H[d, :d] = -X_k u / w
        np.negative(last, out=last)
        return J.reshape(n * d, npar)
    Jt = np.zeros((npar, n, d))
    for k in range(d):
        for j in range(m):
            Jt[k * m + j, :, k] = a[:, j]
    for j in range(d):
        np.multiply(X, -a[:, j:j + 1], out=Jt[d * m + j])
    return Jt.reshape(npar, n * d).T


class RationalModel:
    """The rational map of fixed (normalised) source points ``u`` (n, d) as the engine's
    model and Jacobian; the last evaluation is kept (the engine asks for both at the same
    parameters)."""

    def __init__(self, u: np.ndarray) -> None:
        self.d = u.shape[1]
        self.u1 = homogeneous_points(u)
        self.key = None
        self.X = self.w = None

    def _at(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = p.tobytes()
        if key != self.key:
            self.X, self.w = rational_map(homogeneous_matrix(p, self.d), self.u1)
            self.key = key
        return self.X, self.w

    def model(self, p: np.ndarray) -> np.ndarray:
        return self._at(p)[0].reshape(-1)

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        X, w = self._at(p)
        return rational_jacobian(self.u1, X, w)


def gauss_newton_unit(
    u: np.ndarray,
    X: np.ndarray,
    p0: np.ndarray,
    max_iter: int,
    tol: float,
    u1: np.ndarray | None = None,
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
    u1 : numpy.ndarray, shape (n, d + 1), optional
        ``[u, 1]`` when the caller has it already.

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
    h_flat = np.empty(m * m)
    h_flat[:-1] = p0
    h_flat[-1] = 1.0
    H = h_flat.reshape(m, m)  # a view: updates of h_flat[:-1] update H
    if u1 is None:
        u1 = homogeneous_points(u)
    J = np.zeros((n, d, npar))  # rewritten in place each iteration (the zeros stay)
    v, w, Hx, cost = _residuals(H, u1, X)
    for it in range(1, max_iter + 1):
        if not math.isfinite(cost):
            return None
        limit = tol * (1.0 + math.sqrt(cost / (n * d))) + floor
        Jm = rational_jacobian(u1, Hx, w, out=J)
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
        v, w, Hx, cost_new = _residuals(H, u1, X)
        if not (math.isfinite(cost_new) and cost_new <= cost * (1 + 1e-12)):
            return None
        cost = cost_new
    return None


def _residuals(H: np.ndarray, u1: np.ndarray, X: np.ndarray):
    """Residuals (flat), denominators, mapped points and ``v.T v`` of the map ``H``."""
    Hx, w = rational_map(H, u1)
    v = (Hx - X).reshape(-1)
    return v, w, Hx, float(v @ v)
