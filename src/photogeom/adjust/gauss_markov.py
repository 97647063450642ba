"""Gauss-Markov model: linear and nonlinear least squares with full statistics.

Observation equations ``L + v = A x`` (linear) or ``L + v = f(x)`` (nonlinear),
residuals ``v`` = computed minus observed, weights ``P`` (see :mod:`.weighting`),
optional equality constraints ``h(x) = 0`` (redundancy ``r = n - u + c``).

Solves are done on the whitened, column-scaled design matrix by QR, never by
inverting normal equations of raw coordinates. Rank deficiency raises
:class:`~photogeom.errors.DegenerateGeometryError` naming the undetermined parameters.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy.linalg
import scipy.linalg.lapack

from ..errors import ConvergenceError, DegenerateGeometryError, InputError
from .result import Adjustment
from .weighting import Whitener

#: Reciprocal condition number (of the column-scaled design) below which a solve is refused.
RCOND_LIMIT = 1e-12


def _names(names: Sequence[str] | None, u: int) -> tuple[str, ...]:
    if names is None:
        return tuple(f"x{j}" for j in range(u))
    names = tuple(names)
    if len(names) != u:
        raise InputError(f"{len(names)} parameter name(s) for {u} parameter(s)")
    return names


def _rank_check(R: np.ndarray, names: tuple[str, ...], what: str) -> None:
    """Refuse a triangular factor whose condition is hopeless; name the weak parameters."""
    s = np.linalg.svd(R, compute_uv=False)
    if s.size == 0:
        return
    if not np.all(np.isfinite(s)) or s[-1] <= RCOND_LIMIT * s[0]:
        _, _, Vt = np.linalg.svd(R)
        null = Vt[-1]
        weak = [names[j] for j in np.flatnonzero(np.abs(null) > 0.25 * np.abs(null).max())]
        raise DegenerateGeometryError(
            f"{what}: the observations do not determine the parameters "
            f"({', '.join(weak)} are undetermined or linearly dependent; reciprocal condition "
            f"{(s[-1] / s[0]) if s[0] > 0 else 0.0:.1e}). Add observations with better geometry "
            "or fix those parameters"
        )


def _qr_r_only(M: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R factor of ``M`` and ``Q.T b`` from one QR of ``[M, b]`` (Q is never formed)."""
    u = M.shape[1]
    if M.shape[0] <= u:  # square or short: plain reduced QR
        Q, R = np.linalg.qr(M, mode="reduced")
        return R, Q.T @ b
    Raug = np.linalg.qr(np.column_stack([M, b]), mode="r")
    return Raug[:u, :u], Raug[:u, u]


def _tri_inv(R: np.ndarray) -> np.ndarray:
    """Inverse of an upper-triangular matrix (LAPACK trtri, no BLAS threading overhead)."""
    if R.shape[0] == 0:
        return R.copy()
    Rinv, info = scipy.linalg.lapack.dtrtri(R, lower=0)
    if info != 0:
        raise np.linalg.LinAlgError("singular triangular factor")
    return Rinv


def _solve_whitened(
    Aw: np.ndarray,
    bw: np.ndarray,
    names: tuple[str, ...],
    H: np.ndarray | None = None,
    h: np.ndarray | None = None,
    what: str = "least squares",
) -> tuple[np.ndarray, np.ndarray]:
    """Minimise ``|Aw dx - bw|^2`` (subject to ``H dx = h``); return ``dx`` and ``Qxx``."""
    c = np.linalg.norm(Aw, axis=0)
    if H is not None:
        c = np.maximum(c, np.linalg.norm(H, axis=0))
    zero = c == 0
    if np.any(zero):
        missing = ", ".join(names[j] for j in np.flatnonzero(zero))
        raise DegenerateGeometryError(
            f"{what}: no observation depends on {missing}; the parameter(s) cannot be estimated"
        )
    As = Aw / c
    if H is None:
        R, qtb = _qr_r_only(As, bw)
        _rank_check(R, names, what)
        Rinv = _tri_inv(R)
        dxs = Rinv @ qtb
        Qs = Rinv @ Rinv.T
    else:
        Hs = H / c
        k = Hs.shape[0]
        Qh, Rh = np.linalg.qr(Hs.T, mode="complete")
        _rank_check(Rh[:k, :k], tuple(f"constraint {i + 1}" for i in range(k)), what)
        Y, Z = Qh[:, :k], Qh[:, k:]
        dx_p = Y @ scipy.linalg.solve_triangular(Rh[:k, :k].T, h, lower=True)
        R, qtb = _qr_r_only(As @ Z, bw - As @ dx_p)
        _rank_check(R, names, what)
        Rinv = _tri_inv(R)
        dxs = dx_p + Z @ (Rinv @ qtb)
        Qs = Z @ (Rinv @ Rinv.T) @ Z.T
    return dxs / c, Qs / np.outer(c, c)


def _statistics(
    A: np.ndarray,
    v: np.ndarray,
    Qxx: np.ndarray,
    wh: Whitener,
    sigma0_prior: float,
    full_limit: int = 20000,
) -> tuple[float, np.ndarray | None, np.ndarray | None]:
    """``v.T P v``, redundancy numbers ``diag(Qvv P)`` and Baarda's normalised residuals."""
    vw = wh.apply(v)
    vtpv = float(vw @ vw)
    if wh.kind == "full" and A.shape[0] > full_limit:
        return vtpv, None, None
    PA = wh.apply_t(wh.apply(A))
    AQ = A @ Qxx
    red = 1.0 - np.sum(AQ * PA, axis=1)
    pqvvp = wh.diag_p() - np.sum((PA @ Qxx) * PA, axis=1)
    pv = wh.apply_t(vw)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(
            pqvvp > 1e-14 * wh.diag_p(), pv / np.sqrt(np.abs(pqvvp)) / sigma0_prior, np.nan
        )
    return vtpv, red, w


def solve_linear(
    A,
    L,
    *,
    weights=None,
    covariance=None,
    sigma0_prior: float = 1.0,
    names: Sequence[str] | None = None,
    constraints: tuple[np.ndarray, np.ndarray] | None = None,
    what: str = "linear least squares",
) -> Adjustment:
    """Linear Gauss-Markov adjustment ``L + v = A x``.

    Parameters
    ----------
    A : array_like, shape (n_obs, u)
        Design matrix.
    L : array_like, shape (n_obs,)
        Observations.
    weights : array_like, shape (n_obs,), optional
        Diagonal of the weight matrix ``P``.
    covariance : array_like, optional
        ``Cll`` (n_obs, n_obs) or block-diagonal (k, b, b); ``P = sigma0_prior^2 Cll^-1``.
    sigma0_prior : float
        A-priori standard deviation of unit weight.
    names : sequence of str, optional
        Parameter names.
    constraints : (H, h), optional
        Linear equality constraints ``H x = h`` with H of shape (c, u).
    what : str
        Name of the problem, used in error messages.

    Returns
    -------
    Adjustment
        With ``residuals = A x - L``.
    """
    A = np.asarray(A, dtype=float)
    L = np.asarray(L, dtype=float).reshape(-1)
    if A.ndim != 2 or A.shape[0] != L.shape[0]:
        raise InputError(
            f"{what}: design matrix {A.shape} does not match {L.shape[0]} observations"
        )
    n, u = A.shape
    names = _names(names, u)
    c = 0 if constraints is None else np.atleast_2d(constraints[0]).shape[0]
    if n + c < u:
        raise InputError(f"{what}: {n} observation(s) and {c} constraint(s) for {u} unknown(s)")
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(L))):
        raise InputError(f"{what}: NaN or infinite values in the design matrix or observations")
    wh = Whitener(n, weights, covariance, sigma0_prior)
    H = h = None
    if constraints is not None:
        H = np.atleast_2d(np.asarray(constraints[0], dtype=float))
        h = np.asarray(constraints[1], dtype=float).reshape(-1)
    x, Qxx = _solve_whitened(wh.apply(A), wh.apply(L), names, H, h, what)
    v = A @ x - L
    vtpv, red, w = _statistics(A, v, Qxx, wh, sigma0_prior)
    return Adjustment(
        x=x,
        names=names,
        residuals=v,
        cofactor=Qxx,
        redundancy=n - u + c,
        n_observations=n,
        vtpv=vtpv,
        sigma0_prior=sigma0_prior,
        redundancy_numbers=red,
        normalized_residuals=w,
        iterations=0,
        converged=True,
        cost_history=(vtpv,),
        message="linear solve",
    )


def numerical_jacobian(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of ``fun`` at ``x`` (step ``1e-6 * max(|x_j|, 1)``)."""
    x = np.asarray(x, dtype=float)
    f0 = np.asarray(fun(x), dtype=float)
    J = np.empty((f0.size, x.size))
    for j in range(x.size):  # loop over parameters, not points
        h = 1e-6 * max(abs(x[j]), 1.0)
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        J[:, j] = (np.asarray(fun(xp)).reshape(-1) - np.asarray(fun(xm)).reshape(-1)) / (2 * h)
    return J


def gauss_markov(
    model: Callable[[np.ndarray], np.ndarray],
    x0,
    observed,
    *,
    jacobian: Callable[[np.ndarray], np.ndarray] | None = None,
    weights=None,
    covariance=None,
    sigma0_prior: float = 1.0,
    names: Sequence[str] | None = None,
    constraints: tuple[Callable, Callable] | None = None,
    max_iter: int = 50,
    tol: float = 1e-10,
    raise_on_failure: bool = True,
    step_control: bool = True,
    what: str = "Gauss-Markov adjustment",
) -> Adjustment:
    """Nonlinear Gauss-Markov adjustment ``L + v = f(x)`` by Gauss-Newton iteration.

    Parameters
    ----------
    model : callable
        ``f(x) -> (n_obs,)`` computed observations.
    x0 : array_like, shape (u,)
        Initial values.
    observed : array_like, shape (n_obs,)
        Observations ``L``.
    jacobian : callable, optional
        ``J(x) -> (n_obs, u)``; central differences when omitted.
    weights, covariance, sigma0_prior, names
        As in :func:`solve_linear`.
    constraints : (h, H), optional
        Callables ``h(x) -> (c,)`` and ``H(x) -> (c, u)`` for constraints ``h(x) = 0``.
    max_iter : int
        Iteration limit.
    tol : float
        Convergence criterion: the step changes the whitened computed observations by at
        most ``tol * (1 + rms(v_w)) + 64 eps max|L_w|`` (in units of sigma0_prior), and
        the constraints hold to the same level.
    raise_on_failure : bool
        Raise :class:`ConvergenceError` when the iteration diverges or reaches
        ``max_iter``; with ``False`` return the last iterate with ``converged=False``.
    step_control : bool
        Halve a Gauss-Newton step (up to 30 times) while it increases ``v.T P v``
        (unconstrained problems only). This only changes the path, not the solution;
        ``False`` gives the classic undamped iteration.

    Returns
    -------
    Adjustment
        Statistics evaluated with the Jacobian at the solution.
    """
    x = np.asarray(x0, dtype=float).reshape(-1).copy()
    L = np.asarray(observed, dtype=float).reshape(-1)
    n, u = L.size, x.size
    names = _names(names, u)
    nc = 0
    if constraints is not None:
        nc = np.atleast_1d(constraints[0](x)).size
    if n + nc < u:
        raise InputError(f"{what}: {n} observation(s) and {nc} constraint(s) for {u} unknown(s)")
    if not np.all(np.isfinite(L)) or not np.all(np.isfinite(x)):
        raise InputError(f"{what}: NaN or infinite values in observations or initial values")
    wh = Whitener(n, weights, covariance, sigma0_prior)
    jac = jacobian if jacobian is not None else (lambda p: numerical_jacobian(model, p))
    Lw_max = float(np.max(np.abs(wh.apply(L)))) if n else 0.0
    floor = 64 * np.finfo(float).eps * Lw_max
    history: list[float] = []
    converged = False
    message = ""
    it = 0
    for it in range(1, max_iter + 1):
        f = np.asarray(model(x), dtype=float).reshape(-1)
        v = f - L
        if not np.all(np.isfinite(v)):
            message = f"diverged at iteration {it}: the model returned NaN or infinite values"
            break
        vw = wh.apply(v)
        cost = float(vw @ vw)
        history.append(cost)
        if len(history) > 2 and cost > 1e12 * max(history[0], 1e-300) + 1e-300:
            message = (
                f"diverged at iteration {it}: v.T P v grew from {history[0]:.3g} to {cost:.3g}"
            )
            break
        A = np.asarray(jac(x), dtype=float)
        Aw = wh.apply(A)
        H = h = None
        if constraints is not None:
            h = -np.atleast_1d(constraints[0](x)).astype(float)
            H = np.atleast_2d(constraints[1](x)).astype(float)
        dx, _ = _solve_whitened(Aw, -vw, names, H, h, what)
        if step_control and constraints is None:
            for _ in range(30):
                f_new = np.asarray(model(x + dx), dtype=float).reshape(-1)
                vw_new = wh.apply(f_new - L)
                if np.all(np.isfinite(vw_new)) and float(vw_new @ vw_new) <= cost * (1 + 1e-12):
                    break
                dx = 0.5 * dx
        step = float(np.max(np.abs(Aw @ dx))) if n else 0.0
        x = x + dx
        rms_vw = float(np.sqrt(cost / max(n, 1)))
        ok_c = True if h is None else float(np.max(np.abs(h))) <= tol * (1 + rms_vw) + floor
        if step <= tol * (1.0 + rms_vw) + floor and ok_c:
            converged = True
            message = f"converged after {it} iteration(s)"
            break
    else:
        message = f"not converged: iteration limit {max_iter} reached"
    if not converged and raise_on_failure:
        raise ConvergenceError(
            f"{what}: {message}. Better initial values (e.g. from a direct solution) or a "
            "larger max_iter may help",
            iterations=it,
        )
    f = np.asarray(model(x), dtype=float).reshape(-1)
    v = f - L
    A = np.asarray(jac(x), dtype=float)
    H = h = None
    if constraints is not None:
        H = np.atleast_2d(constraints[1](x)).astype(float)
        h = np.zeros(H.shape[0])
    if np.all(np.isfinite(A)) and np.all(np.isfinite(v)):
        _, Qxx = _solve_whitened(wh.apply(A), -wh.apply(v), names, H, h, what)
        vtpv, red, w = _statistics(A, v, Qxx, wh, sigma0_prior)
    else:
        Qxx = np.full((u, u), np.nan)
        vtpv, red, w = float("nan"), None, None
    return Adjustment(
        x=x,
        names=names,
        residuals=v,
        cofactor=Qxx,
        redundancy=n - u + nc,
        n_observations=n,
        vtpv=vtpv,
        sigma0_prior=sigma0_prior,
        redundancy_numbers=red,
        normalized_residuals=w,
        iterations=it,
        converged=converged,
        cost_history=tuple(history),
        message=message,
    )
