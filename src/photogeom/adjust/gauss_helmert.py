"""Gauss-Helmert model: condition equations ``g(x, L + v) = 0`` with errors in all observations.

Linearised at ``(x_k, L + v_k)``: ``A dx + B v + w = 0`` with ``A = dg/dx``, ``B = dg/dl`` and
``w = g(x_k, L + v_k) - B v_k``. With ``M = B Qll B.T``:
``dx = -(A.T M^-1 A)^-1 A.T M^-1 w``, ``k = -M^-1 (A dx + w)``, ``v = Qll B.T k``,
``Qxx = (A.T M^-1 A)^-1``, ``v.T P v = (A dx + w).T M^-1 (A dx + w)``, redundancy ``m - u``.

``v`` are the corrections of the observations (adjusted minus observed, the library's residual
sign). ``B`` may be a scipy sparse matrix (e.g. block-diagonal for point-wise conditions).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy.linalg

from ..errors import ConvergenceError, DegenerateGeometryError, InputError
from .gauss_markov import _names, _solve_whitened
from .result import Adjustment
from .weighting import Whitener

#: Above this number of condition equations ``M`` is factorised as a sparse matrix.
DENSE_LIMIT = 3000


def _sparse():
    """scipy.sparse, imported on first use (it is slow to import and rarely needed)."""
    import scipy.sparse
    import scipy.sparse.linalg

    return scipy.sparse


class _MSolver:
    """Solves with ``M = B Qll B.T`` (dense Cholesky or sparse LU)."""

    def __init__(self, B, wh: Whitener, dense_limit: int = DENSE_LIMIT) -> None:
        sparse_b = not isinstance(B, np.ndarray) and _sparse().issparse(B)
        m = B.shape[0]
        if sparse_b and wh.kind in ("unit", "diagonal") and m > dense_limit:
            q = wh.diag_q()
            BQ = B @ _sparse().diags(q)
            self.BQ = BQ.tocsr()
            M = (BQ @ B.T).tocsc()
            try:
                self.lu = _sparse().linalg.splu(M)
            except RuntimeError as exc:
                raise DegenerateGeometryError(
                    "Gauss-Helmert: B Qll B.T is singular (a condition does not depend on any "
                    "observation)"
                ) from exc
            self.sparse = True
        else:
            Bd = B.toarray() if sparse_b else np.asarray(B, dtype=float)
            BQ = wh.q_times(Bd.T).T  # (m, n) = B Qll
            M = BQ @ Bd.T
            try:
                self.chol = scipy.linalg.cholesky(0.5 * (M + M.T), lower=True)
            except np.linalg.LinAlgError as exc:
                raise DegenerateGeometryError(
                    "Gauss-Helmert: B Qll B.T is not positive definite (a condition does not "
                    "depend on any observation, or the covariance is singular)"
                ) from exc
            self.BQ = BQ
            self.sparse = False

    def half(self, X: np.ndarray) -> np.ndarray:
        """``C^-1 X`` with ``M = C C.T`` (dense only)."""
        return scipy.linalg.solve_triangular(self.chol, X, lower=True)

    def solve(self, X: np.ndarray) -> np.ndarray:
        """``M^-1 X``."""
        if self.sparse:
            return self.lu.solve(X)
        return scipy.linalg.cho_solve((self.chol, True), X)

    def qbt(self, k: np.ndarray) -> np.ndarray:
        """``Qll B.T k``."""
        return np.asarray(self.BQ.T @ k).reshape(-1)


def gauss_helmert(
    conditions: Callable[[np.ndarray, np.ndarray], np.ndarray],
    x0,
    observed,
    *,
    jacobian_x: Callable[[np.ndarray, np.ndarray], np.ndarray],
    jacobian_l: Callable[[np.ndarray, np.ndarray], object],
    weights=None,
    covariance=None,
    sigma0_prior: float = 1.0,
    names: Sequence[str] | None = None,
    max_iter: int = 50,
    tol: float = 1e-10,
    raise_on_failure: bool = True,
    what: str = "Gauss-Helmert adjustment",
    dense_limit: int = DENSE_LIMIT,
) -> Adjustment:
    """Iterative Gauss-Helmert adjustment.

    Parameters
    ----------
    conditions : callable
        ``g(x, l) -> (m,)``, zero for the true parameters and observations.
    x0 : array_like, shape (u,)
        Initial values (a direct solution is the usual start).
    observed : array_like, shape (n,)
        Observations ``L``.
    jacobian_x : callable
        ``dg/dx (x, l) -> (m, u)``.
    jacobian_l : callable
        ``dg/dl (x, l) -> (m, n)``, dense or scipy sparse.
    weights, covariance, sigma0_prior, names
        As in :func:`photogeom.adjust.solve_linear` (for the observations ``L``).
    max_iter, tol, raise_on_failure
        As in :func:`photogeom.adjust.gauss_markov`; convergence needs both the parameter
        step and the change of the corrections to be negligible.
    dense_limit : int
        With a sparse ``jacobian_l`` and unit or diagonal weights, ``M`` is factorised as a
        sparse matrix above this number of conditions (default :data:`DENSE_LIMIT`; 0 always
        for sparse ``B``, e.g. point-wise conditions whose ``M`` is diagonal). The sparse
        path does not compute redundancy numbers or normalised residuals.
    what : str
        Name of the problem, used in error messages (e.g. ``"relative orientation"``).

    Returns
    -------
    Adjustment
        ``residuals`` are the corrections ``v`` (adjusted minus observed),
        ``corrected_observations = L + v``.
    """
    x = np.asarray(x0, dtype=float).reshape(-1).copy()
    L = np.asarray(observed, dtype=float).reshape(-1)
    n, u = L.size, x.size
    names = _names(names, u)
    if not (np.all(np.isfinite(L)) and np.all(np.isfinite(x))):
        raise InputError(f"{what}: NaN or infinite values in observations or initial values")
    wh = Whitener(n, weights, covariance, sigma0_prior)
    v = np.zeros(n)
    history: list[float] = []
    converged = False
    message = ""
    Lw_max = float(np.max(np.abs(wh.apply(L)))) if n else 0.0
    floor = 64 * np.finfo(float).eps * max(Lw_max, 1.0)
    it = 0
    m = 0
    Qxx = np.full((u, u), np.nan)
    ms = None
    A = None
    for it in range(1, max_iter + 1):
        lk = L + v
        g = np.asarray(conditions(x, lk), dtype=float).reshape(-1)
        m = g.size
        if m < u:
            raise InputError(f"{what}: {m} condition(s) for {u} unknown(s)")
        A = np.asarray(jacobian_x(x, lk), dtype=float)
        B = jacobian_l(x, lk)
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(A))):
            message = f"diverged at iteration {it}: non-finite conditions"
            break
        w = g - np.asarray(B @ v).reshape(-1)
        ms = _MSolver(B, wh, dense_limit)
        if ms.sparse:
            MiA = ms.solve(A)
            Miw = ms.solve(w)
            N = A.T @ MiA
            c = np.sqrt(np.abs(np.diag(N)))
            if np.any(c == 0):
                raise DegenerateGeometryError(f"{what}: a parameter does not enter any condition")
            Ns = N / np.outer(c, c)
            try:
                cf = scipy.linalg.cho_factor(Ns)
            except np.linalg.LinAlgError as exc:
                raise DegenerateGeometryError(
                    f"{what}: normal equations are singular; the parameters are not determined"
                ) from exc
            dx = -scipy.linalg.cho_solve(cf, (A.T @ Miw) / c) / c
            Qxx = scipy.linalg.cho_solve(cf, np.eye(u)) / np.outer(c, c)
            resid = A @ dx + w
            k = -ms.solve(resid)
            cost = float(resid @ -k)
        else:
            At = ms.half(A)
            wt = ms.half(w)
            dx, Qxx = _solve_whitened(At, -wt, names, what=what)
            rt = At @ dx + wt
            cost = float(rt @ rt)
            k = -ms.solve(A @ dx + w)
        v_new = ms.qbt(k)
        history.append(cost)
        dv = float(np.max(np.abs(wh.apply(v_new - v)))) if n else 0.0
        if ms.sparse:  # step scaled by sqrt(diag(A.T M^-1 A)): its effect in sigma units
            step = float(np.max(np.abs(dx) * c))
        else:
            step = float(np.max(np.abs(ms.half(A @ dx))))
        x = x + dx
        v = v_new
        rms = float(np.sqrt(cost / max(m, 1)))
        if step <= tol * (1 + rms) + floor and dv <= tol * (1 + rms) + floor:
            converged = True
            message = f"converged after {it} iteration(s)"
            break
        if len(history) > 2 and history[-1] > 1e12 * max(history[0], 1e-300) + 1e-300:
            message = f"diverged at iteration {it}"
            break
    else:
        message = f"not converged: iteration limit {max_iter} reached"
    if not converged and raise_on_failure:
        raise ConvergenceError(
            f"{what}: {message}. Start from a direct solution or raise max_iter", iterations=it
        )
    vw = wh.apply(v)
    vtpv = float(vw @ vw)
    red = wnorm = None
    if ms is not None and not ms.sparse and n <= 20000 and wh.kind in ("unit", "diagonal"):
        BQ = np.asarray(ms.BQ)
        S = ms.solve(BQ)  # M^-1 B Qll, (m, n)
        K = A.T @ S
        qvv = np.sum(BQ * S, axis=0) - np.sum(K * (Qxx @ K), axis=0)
        p = wh.diag_p()
        red = qvv * p
        with np.errstate(invalid="ignore", divide="ignore"):
            wnorm = np.where(red > 1e-14, v / np.sqrt(np.abs(qvv)) / sigma0_prior, np.nan)
    elif ms is not None and not ms.sparse and n <= 20000:
        # correlated observations (per-block or full covariance), as the Gauss-Markov engine
        # does: diag(Qvv P) and w = (P v)_i / (sigma0_prior sqrt((P Qvv P)_ii)), with
        # Qvv = Qll B' M^-1 (B Qll - A Qxx A' M^-1 B Qll) and P Qll = I
        BQ = np.asarray(ms.BQ)
        Bd = B.toarray() if not isinstance(B, np.ndarray) else np.asarray(B, dtype=float)
        S = ms.solve(BQ)  # M^-1 B Qll
        T = ms.solve(Bd)  # M^-1 B
        K, K2 = A.T @ S, A.T @ T
        red = np.sum(BQ * T, axis=0) - np.sum(K * (Qxx @ K2), axis=0)
        pqvvp = np.sum(Bd * T, axis=0) - np.sum(K2 * (Qxx @ K2), axis=0)
        pv = wh.apply_t(vw)
        with np.errstate(invalid="ignore", divide="ignore"):
            wnorm = np.where(
                pqvvp > 1e-14 * wh.diag_p(), pv / np.sqrt(np.abs(pqvvp)) / sigma0_prior, np.nan
            )
    return Adjustment(
        x=x,
        names=names,
        residuals=v,
        cofactor=Qxx,
        redundancy=m - u,
        n_observations=n,
        vtpv=vtpv,
        sigma0_prior=sigma0_prior,
        redundancy_numbers=red,
        normalized_residuals=wnorm,
        iterations=it,
        converged=converged,
        cost_history=tuple(history),
        message=message,
        corrected_observations=L + v,
    )
