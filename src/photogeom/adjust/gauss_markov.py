"""Gauss-Markov model: linear and nonlinear least squares with full statistics.

Observation equations ``L + v = A x`` (linear) or ``L + v = f(x)`` (nonlinear),
residuals ``v`` = computed minus observed, weights ``P`` (see :mod:`.weighting`),
optional equality constraints ``h(x) = 0`` (redundancy ``r = n - u + c``).

Solves are done on the whitened, column-scaled design matrix, never by inverting normal
equations of raw coordinates: by QR (Householder, R factor only, the right-hand side
appended), and for tall problems (:data:`NORMAL_FROM` rows and more) by the normal equations
of the column-scaled design with a Cholesky factor and one step of iterative refinement
(corrected semi-normal equations), used only when the factor proves the design well
conditioned (:data:`NORMAL_COND_LIMIT`); otherwise a blocked QR. Rank deficiency raises
:class:`~photogeom.errors.DegenerateGeometryError` naming the undetermined parameters.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import scipy.linalg
import scipy.linalg.lapack as _lapack

from ..errors import ConvergenceError, DegenerateGeometryError, InputError
from ..records import build
from .result import Adjustment, not_computed
from .weighting import Whitener

#: Reciprocal condition number (of the column-scaled design) below which a solve is refused.
RCOND_LIMIT = 1e-12
#: From this many observations on (and :data:`NORMAL_ROWS_PER_UNKNOWN` per unknown),
#: unconstrained solves try the normal equations of the column-scaled design.
NORMAL_FROM = 4096
NORMAL_ROWS_PER_UNKNOWN = 16
#: Largest bound ``||R||_F ||R^-1||_F`` on the condition number of the column-scaled design
#: for which the normal equations are used (their own condition is the square, <= 1e10,
#: and one refinement step restores the accuracy of QR); above it a blocked QR is used.
NORMAL_COND_LIMIT = 1e5
#: Rows per block of the blocked (tall-skinny) QR.
QR_BLOCK = 512

_EPS = float(np.finfo(float).eps)


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


_TRIU: dict[int, np.ndarray] = {}


def _upper(T: np.ndarray) -> np.ndarray:
    """Upper triangle of a square matrix (a new array; the strictly lower part zero)."""
    k = T.shape[0]
    mask = _TRIU.get(k)
    if mask is None:
        mask = _TRIU[k] = np.triu(np.ones((k, k)))
    return T * mask


def _frob2(M: np.ndarray) -> float:
    """Squared Frobenius norm."""
    return float(np.vdot(M, M))


def _inverse_checked(R: np.ndarray, names: tuple[str, ...], what: str) -> np.ndarray:
    """``R^-1`` of an upper-triangular factor (strictly lower part zero), after the rank check.

    ``cond_2(R) <= ||R||_F ||R^-1||_F``: when that bound is below ``1 / RCOND_LIMIT`` the
    check passes without a singular value decomposition; otherwise the exact check of
    :func:`_rank_check` decides (and raises with the undetermined parameters named).
    """
    if R.shape[0] == 0:
        return R.copy()
    Rinv, info = _lapack.dtrtri(R, lower=0)
    if info == 0:
        fi = _frob2(Rinv)
        if math.isfinite(fi) and _frob2(R) * fi < RCOND_LIMIT**-2:
            return Rinv
    _rank_check(R, names, what)
    if info != 0 or not np.all(np.isfinite(Rinv)):  # pragma: no cover - passed the SVD check
        Rinv = scipy.linalg.solve_triangular(R, np.eye(R.shape[0]))
    return Rinv


def _qr_factor(M: np.ndarray, b: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """R factor (upper, square, strictly lower part zero) of ``M`` and ``Q.T b``, from one
    Householder QR of ``[M, b]`` (Q is never formed); blocked for very tall M."""
    m, u = M.shape
    k = u if b is None else u + 1
    if m < k:  # square (u = m) with a right-hand side: plain reduced QR
        Q, R = np.linalg.qr(M, mode="reduced")
        return R, None if b is None else Q.T @ b
    if m >= 8 * QR_BLOCK and m >= 64 * k:
        Mb = M if b is None else np.column_stack([M, b])
        Raug = _upper(_tsqr(Mb)[:k])
    else:
        F = np.empty((m, k), order="F")
        F[:, :u] = M
        if b is not None:
            F[:, u] = b
        qr, _tau, _work, info = _lapack.dgeqrf(F, overwrite_a=1)
        if info != 0:  # pragma: no cover - LAPACK argument error
            raise np.linalg.LinAlgError("QR factorisation failed")
        Raug = _upper(qr[:k])
    return (Raug[:u, :u], None) if b is None else (Raug[:u, :u], Raug[:u, u])


def r_factor(M: np.ndarray) -> np.ndarray:
    """Upper-triangular factor R (``min(m, u)`` x u, strictly lower part zero) of ``M = Q R``
    (m x u; Householder QR, blocked for very tall M; Q is never formed)."""
    M = np.asarray(M, dtype=float)
    if M.shape[0] < M.shape[1]:
        return np.linalg.qr(M, mode="r")
    return _qr_factor(M, None)[0]


def _tsqr(M: np.ndarray) -> np.ndarray:
    """R factor of a tall matrix by a tall-skinny QR: batched QR of row blocks, then of the
    stacked block factors (rows in any order; Q is never formed)."""
    m, k = M.shape
    if m <= 8 * QR_BLOCK:
        return np.linalg.qr(M, mode="r")
    nb = m // QR_BLOCK
    parts = [np.linalg.qr(M[: nb * QR_BLOCK].reshape(nb, QR_BLOCK, k), mode="r").reshape(-1, k)]
    if m > nb * QR_BLOCK:
        parts.append(M[nb * QR_BLOCK :])
    return _tsqr(np.vstack(parts))


def _column_scale(Aw: np.ndarray, H: np.ndarray | None, names, what) -> np.ndarray:
    c = np.sqrt(np.einsum("ij,ij->j", Aw, Aw))
    if H is not None:
        c = np.maximum(c, np.sqrt(np.einsum("ij,ij->j", H, H)))
    _no_observation(c, names, what)
    return c


def _no_observation(c: np.ndarray, names, what) -> None:
    """Raise when a column of the design is zero (no observation depends on it)."""
    if c.all():
        return
    zero = c == 0
    if np.any(zero):
        missing = ", ".join(names[j] for j in np.flatnonzero(zero))
        raise DegenerateGeometryError(
            f"{what}: no observation depends on {missing}; the parameter(s) cannot be estimated"
        )


def _normal_path(m: int, u: int) -> bool:
    return m >= NORMAL_FROM and m >= NORMAL_ROWS_PER_UNKNOWN * u


def _solve_normal(Aw: np.ndarray, bw: np.ndarray | None, names, what):
    """Corrected semi-normal equations of the column-scaled design (see module docstring).

    Returns ``(dx, F)`` with ``Qxx = F F.T``, or None when the design is not well enough
    conditioned for them (the caller then uses QR)."""
    N = Aw.T @ Aw
    d = np.diagonal(N)
    _no_observation(d, names, what)
    if not np.isfinite(d).all():
        return None  # the QR path reports it
    c = np.sqrt(d)
    Ns = N / np.outer(c, c)
    R, info = _lapack.dpotrf(Ns, lower=0, clean=1)
    if info != 0:
        return None
    Rinv, info = _lapack.dtrtri(R, lower=0)
    if info != 0:
        return None
    fi = _frob2(Rinv)
    if not (math.isfinite(fi) and _frob2(R) * fi < NORMAL_COND_LIMIT**2):
        return None
    F = Rinv / c[:, None]  # Qxx = F F.T
    if bw is None:
        return None, F
    Qs = Rinv @ Rinv.T
    g = (Aw.T @ bw) / c
    ys = Qs @ g
    # one step of iterative refinement with the residual of the original system
    r = bw - Aw @ (ys / c)
    ys = ys + Qs @ ((Aw.T @ r) / c)
    return ys / c, F


def _solve(
    Aw: np.ndarray,
    bw: np.ndarray | None,
    names: tuple[str, ...],
    H: np.ndarray | None = None,
    h: np.ndarray | None = None,
    what: str = "least squares",
    factor: bool = True,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Minimise ``|Aw dx - bw|^2`` (subject to ``H dx = h``).

    Returns ``dx`` (None when ``bw`` is None: factor only) and ``F`` with ``Qxx = F F.T``
    (None unless ``factor``).
    """
    m, u = Aw.shape
    if H is None and _normal_path(m, u):
        out = _solve_normal(Aw, bw, names, what)
        if out is not None:
            return out
    c = _column_scale(Aw, H, names, what)
    As = Aw / c
    if H is None:
        R, qtb = _qr_factor(As, bw)
        Rinv = _inverse_checked(R, names, what)
        dxs = None if qtb is None else Rinv @ qtb
        Fs = Rinv
    else:
        Hs = H / c
        k = Hs.shape[0]
        Qh, Rh = np.linalg.qr(Hs.T, mode="complete")
        _rank_check(Rh[:k, :k], tuple(f"constraint {i + 1}" for i in range(k)), what)
        Y, Z = Qh[:, :k], Qh[:, k:]
        dx_p = Y @ scipy.linalg.solve_triangular(Rh[:k, :k].T, h, lower=True)
        R, qtb = _qr_factor(As @ Z, bw - As @ dx_p)
        Rinv = _inverse_checked(R, names, what)
        dxs = dx_p + Z @ (Rinv @ qtb)
        Fs = Z @ Rinv
    return (None if dxs is None else dxs / c), (Fs / c[:, None] if factor else None)


def _solve_whitened(
    Aw: np.ndarray,
    bw: np.ndarray,
    names: tuple[str, ...],
    H: np.ndarray | None = None,
    h: np.ndarray | None = None,
    what: str = "least squares",
) -> tuple[np.ndarray, np.ndarray]:
    """Minimise ``|Aw dx - bw|^2`` (subject to ``H dx = h``); return ``dx`` and ``Qxx``."""
    dx, F = _solve(Aw, bw, names, H, h, what)
    return dx, F @ F.T


def _statistics(
    A: np.ndarray,
    v: np.ndarray,
    F: np.ndarray,
    wh: Whitener,
    sigma0_prior: float,
    Aw: np.ndarray | None = None,
    full_limit: int = 20000,
) -> tuple[float, np.ndarray | None, np.ndarray | None]:
    """``v.T P v``, redundancy numbers ``diag(Qvv P)`` and Baarda's normalised residuals.

    ``Qxx = F F.T``. With unit or diagonal weights ``diag(Qvv P) = 1 - h`` with
    ``h = rowsum((W A F)^2)`` and ``w = (W v) / (sigma0_prior sqrt(1 - h))`` (one product
    with the u x u factor); correlated observations use ``P Qvv P`` in full.
    """
    vw = wh.apply(v)
    vtpv = float(vw @ vw)
    if wh.kind in ("unit", "diagonal"):
        G = (wh.apply(A) if Aw is None else Aw) @ F
        red = 1.0 - np.einsum("ij,ij->i", G, G)
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(red > 1e-14, vw / np.sqrt(np.abs(red)) / sigma0_prior, np.nan)
        return vtpv, red, w
    if wh.kind == "full" and A.shape[0] > full_limit:
        return vtpv, None, None
    Qxx = F @ F.T
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


def bare_adjustment(
    x, names, n, u, redundancy, sigma0_prior, iterations, converged, history, message
) -> Adjustment:
    """An Adjustment without statistics (``statistics=False``): the estimate ``x`` of ``u``
    parameters from ``n`` observations, NaN cofactor (read-only), no residuals."""
    return build(
        Adjustment,
        {
            "x": x,
            "names": names,
            "residuals": not_computed((0,)),
            "cofactor": not_computed((u, u)),
            "redundancy": redundancy,
            "n_observations": n,
            "vtpv": math.nan,
            "sigma0_prior": sigma0_prior,
            "iterations": iterations,
            "converged": converged,
            "cost_history": history,
            "message": message,
        },
    )


def solve_linear(
    A,
    L,
    *,
    weights=None,
    covariance=None,
    sigma0_prior: float = 1.0,
    names: Sequence[str] | None = None,
    constraints: tuple[np.ndarray, np.ndarray] | None = None,
    statistics: bool = True,
    check_finite: bool = True,
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
    statistics : bool
        ``False`` returns the estimate only: ``residuals`` empty, ``cofactor`` and ``vtpv``
        NaN, no redundancy numbers or normalised residuals (the estimate is the same).
    check_finite : bool
        ``False`` skips the NaN / inf check of ``A`` and ``L`` (for callers that have
        validated them).
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
    if check_finite and not (np.isfinite(A).all() and np.isfinite(L).all()):
        raise InputError(f"{what}: NaN or infinite values in the design matrix or observations")
    wh = Whitener(n, weights, covariance, sigma0_prior)
    H = h = None
    if constraints is not None:
        H = np.atleast_2d(np.asarray(constraints[0], dtype=float))
        h = np.asarray(constraints[1], dtype=float).reshape(-1)
    Aw = wh.apply(A)
    x, F = _solve(Aw, wh.apply(L), names, H, h, what)
    if not statistics:
        return bare_adjustment(x, names, n, u, n - u + c, sigma0_prior, 0, True, (), "linear solve")
    v = A @ x - L
    vtpv, red, w = _statistics(A, v, F, wh, sigma0_prior, Aw)
    return Adjustment(
        x=x,
        names=names,
        residuals=v,
        cofactor=F @ F.T,
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


def _flat(values) -> np.ndarray:
    return np.asarray(values, dtype=float).reshape(-1)


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
    statistics: bool = True,
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
        (unconstrained problems only; a step already within the convergence tolerance is
        taken as it is). This only changes the path, not the solution; ``False`` gives the
        classic undamped iteration.
    statistics : bool
        ``False`` skips the evaluation at the solution: the same estimate (the same
        iterations), with ``residuals`` empty, ``cofactor`` and ``vtpv`` NaN and no
        redundancy numbers or normalised residuals.
    what : str
        Name of the problem, used in error messages (e.g. ``"space resection"``).

    Returns
    -------
    Adjustment
        Statistics evaluated with the Jacobian at the solution.
    """
    x = _flat(x0).copy()
    L = _flat(observed)
    n, u = L.size, x.size
    names = _names(names, u)
    nc = 0
    if constraints is not None:
        nc = np.atleast_1d(constraints[0](x)).size
    if n + nc < u:
        raise InputError(f"{what}: {n} observation(s) and {nc} constraint(s) for {u} unknown(s)")
    if not (np.isfinite(L).all() and np.isfinite(x).all()):
        raise InputError(f"{what}: NaN or infinite values in observations or initial values")
    wh = Whitener(n, weights, covariance, sigma0_prior)
    jac = jacobian if jacobian is not None else (lambda p: numerical_jacobian(model, p))
    Lw_max = float(abs(wh.apply(L)).max()) if n else 0.0
    floor = 64 * _EPS * Lw_max
    history: list[float] = []
    converged = False
    message = ""
    it = 0
    f = None  # computed observations at x when already known (from the step control)
    for it in range(1, max_iter + 1):
        if f is None:
            f = _flat(model(x))
        v = f - L
        vw = wh.apply(v)
        cost = float(vw @ vw)
        if not math.isfinite(cost):
            message = f"diverged at iteration {it}: the model returned NaN or infinite values"
            break
        history.append(cost)
        if len(history) > 2 and cost > 1e12 * max(history[0], 1e-300) + 1e-300:
            message = (
                f"diverged at iteration {it}: v.T P v grew from {history[0]:.3g} to {cost:.3g}"
            )
            break
        Aw = wh.apply(_as_matrix(jac(x)))
        H = h = None
        if constraints is not None:
            h = -np.atleast_1d(constraints[0](x)).astype(float)
            H = np.atleast_2d(constraints[1](x)).astype(float)
        dx, _ = _solve(Aw, -vw, names, H, h, what, factor=False)
        step = float(abs(Aw @ dx).max()) if n else 0.0
        rms_vw = math.sqrt(cost / max(n, 1))
        limit = tol * (1.0 + rms_vw) + floor
        f = None
        if step_control and constraints is None and step > limit:
            halved = 0
            for halved in range(31):
                x_new = x + dx
                if halved == 30:
                    break  # 30 halvings: take the (tiny) step as it is
                f_new = _flat(model(x_new))
                vw_new = wh.apply(f_new - L)
                cost_new = float(vw_new @ vw_new)
                if math.isfinite(cost_new) and cost_new <= cost * (1 + 1e-12):
                    f = f_new  # the model at the new x, for the next iteration
                    break
                dx = 0.5 * dx
            if halved:
                step = float(abs(Aw @ dx).max())
            x = x_new
        else:
            x = x + dx
        ok_c = True if h is None else float(abs(h).max()) <= limit
        if step <= limit and ok_c:
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
    if not statistics:
        return bare_adjustment(
            x, names, n, u, n - u + nc, sigma0_prior, it, converged, tuple(history), message
        )
    if f is None:
        f = _flat(model(x))
    v = f - L
    A = _as_matrix(jac(x))
    H = h = None
    if constraints is not None:
        H = np.atleast_2d(constraints[1](x)).astype(float)
        h = np.zeros(H.shape[0])
    if np.isfinite(A).all() and np.isfinite(v).all():
        Aw = wh.apply(A)
        _, F = _solve(Aw, None if H is None else -wh.apply(v), names, H, h, what)
        Qxx = F @ F.T
        vtpv, red, w = _statistics(A, v, F, wh, sigma0_prior, Aw)
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


def _as_matrix(A) -> np.ndarray:
    A = np.asarray(A, dtype=float)
    return A if A.ndim == 2 else A.reshape(A.shape[0], -1)
