"""Estimation of the transformation models from point pairs, with full statistics.

:func:`estimate_transform` fits one of the models of :mod:`photogeom.transforms` to control
points (source -> target) by least squares through the engine of :mod:`photogeom.adjust` and
returns a :class:`~photogeom.adjust.Fit`:

* linear models (2D similarity, affine, polynomial; 3D affine, polynomial): QR least squares
  on centred and scaled source coordinates and centred target coordinates; parameters and
  their cofactor matrix are transformed back exactly (``J Qxx J.T``). For many points, models
  whose coordinates share one design (affine, polynomial) are solved one coordinate at a time
  with the same statistics as the joint system;
* projective models: a linearised least-squares start (the lecture's form with the
  observations on both sides), then a nonlinear Gauss-Markov adjustment of the rational
  form (errors in the target) or a Gauss-Helmert adjustment (errors in both point sets);
* 3D similarity and rigid: :func:`photogeom.orientation.absolute.absolute_orientation`.

Residuals are computed minus observed, in the target system. Check points do not enter the
estimate; their residuals are attached to the Fit.

Observation order for weights and covariances: point by point, ``x1, y1, x2, y2, ...``
(3D: ``x, y, z``); with ``errors_in="both"``: ``x'1, y'1, x1, y1, ...`` (source first).
"""

from __future__ import annotations

import inspect
import itertools
import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg
import scipy.sparse

from ..adjust import Adjustment, Fit, gauss_helmert, gauss_markov, normalize_points, solve_linear
from ..errors import DegenerateGeometryError, InputError
from ..imagecoords import handedness_plan
from ..transforms import (
    Affine2D,
    Affine3D,
    Polynomial2D,
    Polynomial3D,
    Projective2D,
    Projective3D,
    Rigid3D,
    Similarity2D,
    Similarity3D,
    polynomial_exponents,
    polynomial_term_count,
    polynomial_terms,
)
from ..validation import as_points, check_count, check_same_length

#: Models accepted by :func:`estimate_transform` and their coordinate dimension.
MODELS: dict[str, int] = {
    "similarity2d": 2,
    "affine2d": 2,
    "projective2d": 2,
    "polynomial2d": 2,
    "rigid3d": 3,
    "similarity3d": 3,
    "affine3d": 3,
    "projective3d": 3,
    "polynomial3d": 3,
}

#: From this many control points on, models with one design shared by all coordinates
#: (affine, polynomial) are solved coordinate by coordinate (same statistics, less work).
SEPARABLE_FROM = 2000

#: From this many condition equations on, the Gauss-Helmert B matrix is built sparse.
SPARSE_FROM = 3000

#: Relative size of the smallest singular value of the centred points below which the points
#: are treated as collinear / coplanar.
RANK_TOLERANCE = 1e-10

_METHOD_LINEAR = "linear least squares (QR)"


@dataclass(frozen=True)
class _Observations:
    """Weights / covariance of the control observations in one of the engine's forms."""

    weights: np.ndarray | None  # (n, k) per observation, or None
    covariance: np.ndarray | None  # (n, k, k) blocks or (n k, n k) full, or None

    @property
    def separable(self) -> bool:
        return self.covariance is None

    def flat_weights(self) -> np.ndarray | None:
        return None if self.weights is None else self.weights.reshape(-1)


# --- input handling ----------------------------------------------------------------------------


def _stochastic_model(weights, covariance, n: int, k: int, mask: np.ndarray) -> _Observations:
    """Weights (n,) or (n, k), or covariance (n, k, k) or (n k, n k), restricted to ``mask``."""
    if weights is not None and covariance is not None:
        raise InputError("give either weights or a covariance, not both")
    if weights is not None:
        w = np.asarray(weights, dtype=float)
        if w.ndim == 1 and w.shape[0] == n:
            w = np.repeat(w[:, None], k, axis=1)
        elif w.shape != (n, k):
            raise InputError(
                f"weights: expected shape ({n},) (one per point) or ({n}, {k}) (one per "
                f"coordinate), got {w.shape}"
            )
        if not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise InputError("weights must be finite and > 0")
        return _Observations(w[mask], None)
    if covariance is not None:
        C = np.asarray(covariance, dtype=float)
        if C.shape == (n, k, k):
            C = C[mask]
        elif C.shape == (n * k, n * k):
            idx = np.flatnonzero(np.repeat(mask, k))
            C = C[np.ix_(idx, idx)]
        else:
            raise InputError(
                f"covariance: expected shape ({n}, {k}, {k}) (one block per point) or "
                f"({n * k}, {n * k}) (full, observations point by point), got {C.shape}"
            )
        if not np.all(np.isfinite(C)):
            raise InputError("covariance contains NaN or infinite values")
        return _Observations(None, C)
    return _Observations(None, None)


def _flip_stochastic(obs: _Observations, signs: np.ndarray) -> _Observations:
    """Stochastic model of observations multiplied by +-1 (``signs`` per coordinate)."""
    if obs.covariance is None:
        return obs
    C = obs.covariance
    if C.ndim == 3:
        return _Observations(None, C * np.outer(signs, signs))
    ss = np.tile(signs, C.shape[0] // signs.size)
    return _Observations(None, C * np.outer(ss, ss))


def _whitened_scale(obs: _Observations, factors: np.ndarray) -> tuple:
    """(weights, covariance) for the engine when observations are divided by ``factors``."""
    f = np.asarray(factors, dtype=float)
    if obs.covariance is not None:
        C = obs.covariance
        if C.ndim == 3:
            return None, C / np.outer(f, f)
        ff = np.tile(f, C.shape[0] // f.size)
        return None, C / np.outer(ff, ff)
    base = obs.weights
    if base is None:
        return None, None
    return (base * f**2).reshape(-1), None


def _unit_weights_scaled(n: int, factors: np.ndarray, obs: _Observations):
    """Engine weights/covariance for normalised observations (observation / factor)."""
    f = np.asarray(factors, dtype=float)
    if obs.covariance is None and obs.weights is None:
        if np.all(f == 1.0):
            return None, None
        return np.tile(f**2, n), None
    return _whitened_scale(obs, f)


def _ids(ids, n: int) -> np.ndarray | None:
    """Point ids as an array (None: rows are numbered 1..n)."""
    if ids is None:
        return None
    arr = np.asarray(ids)
    if arr.ndim != 1 or arr.shape[0] != n:
        raise InputError(f"ids: {arr.size} id(s) for {n} point(s)")
    uniq, counts = np.unique(arr.astype(str), return_counts=True)
    if uniq.size != n:
        shown = ", ".join(map(str, uniq[counts > 1][:10]))
        raise InputError(f"ids: duplicate id(s) {shown}; ids must be unique")
    return arr


def _select_ids(ids: np.ndarray | None, mask: np.ndarray, numbered: bool) -> tuple | None:
    """Ids of the rows in ``mask`` (row numbers 1..n when no ids were given and
    ``numbered``; None when no ids were given and all rows are selected)."""
    if ids is None:
        return tuple((np.flatnonzero(mask) + 1).tolist()) if numbered else None
    return tuple(ids[mask].tolist())


def _check_mask(check, n: int) -> np.ndarray:
    if check is None:
        return np.zeros(n, dtype=bool)
    c = np.asarray(check)
    if c.shape != (n,):
        raise InputError(f"check: expected a boolean mask of shape ({n},), got shape {c.shape}")
    if c.dtype != bool:
        if not np.all(np.isin(c, (0, 1))):
            raise InputError("check: expected a boolean mask (True marks a check point)")
        c = c.astype(bool)
    return c


def _min_points(model: str, order: int | None) -> int:
    return {
        "similarity2d": 2,
        "affine2d": 3,
        "projective2d": 4,
        "rigid3d": 3,
        "similarity3d": 3,
        "affine3d": 4,
        "projective3d": 5,
    }.get(model) or polynomial_term_count(order, MODELS[model])


def _hint(model: str, order: int | None) -> str:
    return {
        "similarity2d": "4 parameters, 2 equations per point",
        "affine2d": "6 parameters, 2 equations per point",
        "projective2d": "8 parameters, 2 equations per point",
        "rigid3d": "3 points not on one line",
        "similarity3d": "3 points not on one line",
        "affine3d": "12 parameters, 3 equations per point",
        "projective3d": "15 parameters, 3 equations per point",
    }.get(model) or (
        f"order {order}: {polynomial_term_count(order, MODELS[model])} coefficients per coordinate"
    )


def _rank(points: np.ndarray) -> tuple[int, np.ndarray]:
    """Numerical rank of the centred point set (0 = all coincide) and its singular values."""
    c = points - points.mean(axis=0)
    mag = max(float(np.max(np.abs(points))), 1e-300)
    if float(np.max(np.abs(c))) <= 1e-13 * mag:
        return 0, np.zeros(points.shape[1])
    if c.shape[0] <= 5000:
        s = np.linalg.svd(c, compute_uv=False)
    else:  # many points: the scatter matrix, and a QR only when that is ambiguous
        ev = np.linalg.eigvalsh(c.T @ c)
        s = np.sqrt(np.clip(ev[::-1], 0.0, None))
        if s[-1] <= 1e-6 * s[0]:
            s = np.linalg.svd(np.linalg.qr(c, mode="r"), compute_uv=False)
    return int(np.sum(s > RANK_TOLERANCE * s[0])), s


def _geometry(points: np.ndarray, need_rank: int, model: str, side: str, need: int) -> None:
    """Raise :class:`DegenerateGeometryError` when the points span fewer dimensions."""
    rank, _ = _rank(points)
    if rank >= need_rank:
        return
    d = points.shape[1]
    if rank == 0:
        raise DegenerateGeometryError(
            f"{model}: all {points.shape[0]} {side} points coincide; at least {need} distinct "
            f"points are needed"
        )
    shape = "collinear (on one line)" if rank == 1 else "coplanar (in one plane)"
    want = "3 points not on one line" if need_rank == 2 else "4 points not in one plane"
    if d == 3 and need_rank == 2:
        want = "3 points not on one line"
    raise DegenerateGeometryError(
        f"{model}: the {points.shape[0]} {side} points are {shape}; the model needs at least "
        f"{want} ({need} points in general position)"
    )


def _general_position(points: np.ndarray, model: str, side: str) -> None:
    """For the minimal projective case: no d+1 of the d+2 points may be dependent."""
    n, d = points.shape
    norm = normalize_points(points)
    u = norm.apply(points)
    h = np.column_stack([u, np.ones(n)])
    for sub in itertools.combinations(range(n), d + 1):
        if abs(np.linalg.det(h[list(sub)])) <= 1e-9:
            what = "three of the four points are collinear" if d == 2 else (
                "four of the five points are coplanar")
            raise DegenerateGeometryError(
                f"{model}: {what} on the {side} side (rows {', '.join(str(i) for i in sub)}); "
                f"with the minimum of {n} points no {d + 1} may be "
                + ("collinear" if d == 2 else "coplanar")
            )


def _validate_geometry(model: str, src: np.ndarray, dst: np.ndarray, need: int) -> None:
    d = src.shape[1]
    if model == "similarity2d":
        _geometry(src, 1, model, "source", need)
    elif model in ("rigid3d", "similarity3d"):
        _geometry(src, 2, model, "source", need)
        _geometry(dst, 2, model, "target", need)
    elif model in ("affine2d", "affine3d", "polynomial2d", "polynomial3d"):
        _geometry(src, d, model, "source", need)
    elif model in ("projective2d", "projective3d"):
        _geometry(src, d, model, "source", need)
        _geometry(dst, d, model, "target", need)
        if src.shape[0] == need:
            _general_position(src, model, "source")
            _general_position(dst, model, "target")


# --- combination of per-coordinate adjustments ---------------------------------------------------


def _combine(parts: list[Adjustment], names: tuple[str, ...]) -> Adjustment:
    """One Adjustment from independent per-coordinate adjustments of the same points
    (observations interleaved point by point, parameters concatenated)."""

    def stack(attr):
        vals = [getattr(a, attr) for a in parts]
        if any(v is None for v in vals):
            return None
        return np.column_stack(vals).reshape(-1)

    return Adjustment(
        x=np.concatenate([a.x for a in parts]),
        names=names,
        residuals=stack("residuals"),
        cofactor=scipy.linalg.block_diag(*[a.cofactor for a in parts]),
        redundancy=sum(a.redundancy for a in parts),
        n_observations=sum(a.n_observations for a in parts),
        vtpv=float(sum(a.vtpv for a in parts)),
        sigma0_prior=parts[0].sigma0_prior,
        redundancy_numbers=stack("redundancy_numbers"),
        normalized_residuals=stack("normalized_residuals"),
        iterations=0,
        converged=True,
        cost_history=(float(sum(a.vtpv for a in parts)),),
        message="linear solve, coordinates solved separately (one shared design)",
    )


def _shared_design_solve(
    D: np.ndarray,
    L: np.ndarray,
    obs: _Observations,
    sigma0_prior: float,
    names: tuple[str, ...],
    what: str,
    force: str | None = None,
) -> Adjustment:
    """Least squares for ``L[:, k] + v = D x_k`` (every coordinate k with the same design D).

    Parameters are ordered coordinate by coordinate; observations point by point. Solved
    per coordinate when the observations of different coordinates are uncorrelated and there
    are many points (``force`` = "joint" / "separate" overrides), else as one joint system.
    """
    n, m = D.shape
    k = L.shape[1]
    mode = force or ("separate" if obs.separable and n >= SEPARABLE_FROM else "joint")
    if mode == "separate":
        if not obs.separable:
            raise InputError(f"{what}: correlated coordinates need the joint solution")
        parts = []
        for j in range(k):
            w = None if obs.weights is None else obs.weights[:, j]
            parts.append(solve_linear(D, L[:, j], weights=w, sigma0_prior=sigma0_prior,
                                      names=names[j * m:(j + 1) * m], what=what))
        return _combine(parts, names)
    A = np.zeros((n, k, k * m))
    for j in range(k):
        A[:, j, j * m:(j + 1) * m] = D
    return solve_linear(
        A.reshape(n * k, k * m),
        L.reshape(-1),
        weights=obs.flat_weights(),
        covariance=obs.covariance,
        sigma0_prior=sigma0_prior,
        names=names,
        what=what,
    )


# --- the linear models -------------------------------------------------------------------------


def _fit_similarity2d(src, dst, obs, sigma0_prior, what):
    ns = normalize_points(src)
    ct = dst.mean(axis=0)
    u = ns.apply(src)
    X = dst - ct
    n = src.shape[0]
    A = np.zeros((n, 2, 4))
    A[:, 0, 0], A[:, 0, 1], A[:, 0, 2] = u[:, 0], u[:, 1], 1.0
    A[:, 1, 0], A[:, 1, 1], A[:, 1, 3] = u[:, 1], -u[:, 0], 1.0
    adj = solve_linear(A.reshape(2 * n, 4), X.reshape(-1), weights=obs.flat_weights(),
                       covariance=obs.covariance, sigma0_prior=sigma0_prior,
                       names=("a", "b", "c", "d"), what=what)
    an, bn, cn, dn = adj.x
    k = ns.scale
    cx, cy = ns.centre
    a, b = an / k, bn / k
    p = np.array([a, b, cn + ct[0] - a * cx - b * cy, dn + ct[1] + b * cx - a * cy])
    J = np.array([
        [1 / k, 0, 0, 0],
        [0, 1 / k, 0, 0],
        [-cx / k, -cy / k, 1, 0],
        [-cy / k, cx / k, 0, 1],
    ])
    return Similarity2D(*p), adj, p, J


def _affine_back(ns, ct, d: int) -> np.ndarray:
    """J for one output row: [a_1..a_d, t] = J @ [an_1..an_d, tn]."""
    k = ns.scale
    Jr = np.zeros((d + 1, d + 1))
    Jr[:d, :d] = np.eye(d) / k
    Jr[d, :d] = -ns.centre / k
    Jr[d, d] = 1.0
    return Jr


def _fit_affine(src, dst, obs, sigma0_prior, what, force=None):
    d = src.shape[1]
    ns = normalize_points(src)
    ct = dst.mean(axis=0)
    D = np.column_stack([ns.apply(src), np.ones(src.shape[0])])
    names_n = tuple(f"{r}{j}" for r in "abc"[:d] for j in range(1, d + 2))
    adj = _shared_design_solve(D, dst - ct, obs, sigma0_prior, names_n, what, force)
    Jr = _affine_back(ns, ct, d)
    xr = adj.x.reshape(d, d + 1)
    rows = xr @ Jr.T  # per output row [a.., t]
    rows[:, d] += ct
    Jrows = scipy.linalg.block_diag(*([Jr] * d))  # row-block order (a1 a2 a3 b1 b2 b3 ...)
    if d == 2:
        p = rows.reshape(-1)
        return Affine2D(*p), adj, p, Jrows
    # Affine3D parameter order: a11..a33, tx, ty, tz
    perm = [r * 4 + j for r in range(3) for j in range(3)] + [3, 7, 11]
    p = rows.reshape(-1)[perm]
    return Affine3D(rows[:, :3], rows[:, 3]), adj, p, Jrows[perm]


def _fit_polynomial(src, dst, order, obs, sigma0_prior, what, force=None):
    d = src.shape[1]
    ns = normalize_points(src)
    ct = dst.mean(axis=0)
    exps = polynomial_exponents(order, d)
    D = polynomial_terms(ns.apply(src), exps)
    cls = Polynomial2D if d == 2 else Polynomial3D
    template = cls(order, np.zeros((d, exps.shape[0])), ns.centre, ns.scale)
    names = template.parameter_names
    adj = _shared_design_solve(D, dst - ct, obs, sigma0_prior, names, what, force)
    C = adj.x.reshape(d, -1).copy()
    C[:, 0] += ct  # the constant monomial is first
    model = cls(order, C, ns.centre, ns.scale)
    return model, adj, model.parameters, None


# --- projective models -------------------------------------------------------------------------


def _affine_rows(M: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``[u, 1] @ M.T`` for points u (n, d) and M (k, d + 1), by columns (fast for small d)."""
    d = u.shape[1]
    out = np.empty((u.shape[0], M.shape[0]))
    for k in range(M.shape[0]):
        col = u[:, 0] * M[k, 0] + M[k, d]
        for j in range(1, d):
            col += u[:, j] * M[k, j]
        out[:, k] = col
    return out


def _proj_rational(p: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rational projective map of (normalised) points: (X (n, d), w (n,), H)."""
    d = u.shape[1]
    H = np.append(p, 1.0).reshape(d + 1, d + 1)
    h = _affine_rows(H, u)
    w = h[:, d]
    return h[:, :d] / w[:, None], w, H


def _proj_jacobian(p: np.ndarray, u: np.ndarray) -> np.ndarray:
    """d X / d p for the rational form, rows point by point: (n d, (d+1)^2 - 1), built
    column by column (Fortran order, as the QR factorisation wants it)."""
    n, d = u.shape
    X, w, _ = _proj_rational(p, u)
    iw = 1.0 / w
    ui = u * iw[:, None]
    Jt = np.zeros(((d + 1) ** 2 - 1, n, d))
    for k in range(d):
        base = k * (d + 1)
        for j in range(d):
            Jt[base + j, :, k] = ui[:, j]
            Jt[d * (d + 1) + j, :, k] = -X[:, k] * ui[:, j]
        Jt[base + d, :, k] = iw
    return Jt.reshape(Jt.shape[0], n * d).T


def _proj_back(p_n: np.ndarray, ns, nt, d: int) -> tuple[np.ndarray, np.ndarray]:
    """Raw parameters and d p_raw / d p_n from normalised ones: H = Tt^-1 H_n Ts / h_last."""
    Ts, Tt_inv = ns.matrix, np.linalg.inv(nt.matrix)
    K = np.kron(Tt_inv, Ts.T)  # vec_row(Tt^-1 H Ts) = K vec_row(H)
    h = K @ np.append(p_n, 1.0)
    last = h[-1]
    if abs(last) <= 1e-14 * np.max(np.abs(h)):
        raise DegenerateGeometryError(
            "projective: the estimated transformation sends the source origin to infinity, so "
            "it cannot be written with its last element 1; shift the source coordinates"
        )
    p = h[:-1] / last
    Kf = K[:, :-1]  # the last normalised element is fixed at 1
    J = (Kf[:-1] - np.outer(p, Kf[-1])) / last
    return p, J


def _proj_forward(p_raw: np.ndarray, ns, nt, d: int) -> np.ndarray:
    """Normalised parameters of a raw projective transformation: H_n = Tt H Ts^-1 / h_last."""
    H = np.append(p_raw, 1.0).reshape(d + 1, d + 1)
    Hn = nt.matrix @ H @ np.linalg.inv(ns.matrix)
    if abs(Hn[-1, -1]) <= 1e-14 * np.max(np.abs(Hn)):
        raise DegenerateGeometryError(
            "projective: the start sends the centroid of the source points to infinity; the "
            "points do not determine a projective transformation"
        )
    return (Hn / Hn[-1, -1]).reshape(-1)[:-1]


def _refine_start(p: np.ndarray, u: np.ndarray, X: np.ndarray, weights, max_steps: int = 8):
    """Initial values for the Gauss-Markov adjustment of the rational form: Gauss-Newton steps
    from ``p`` on the normal equations of the (normalised, hence well-conditioned) problem,
    kept only while they lower ``v.T P v``. This only saves iterations of the adjustment,
    whose estimate and statistics do not depend on it."""
    sw = None if weights is None else np.sqrt(np.asarray(weights, dtype=float))
    L = X.reshape(-1)

    def cost_and_r(q):
        r = _proj_rational(q, u)[0].reshape(-1) - L
        if sw is not None:
            r = r * sw
        return float(r @ r), r

    cost, r = cost_and_r(p)
    for _ in range(max_steps):
        J = _proj_jacobian(p, u)
        if sw is not None:
            J = J * sw[:, None]
        try:
            dp = -scipy.linalg.solve(J.T @ J, J.T @ r, assume_a="pos", check_finite=False)
        except (np.linalg.LinAlgError, ValueError):
            break
        if not np.all(np.isfinite(dp)):
            break
        new_cost, new_r = cost_and_r(p + dp)
        if not new_cost < cost:
            break
        p, cost, r = p + dp, new_cost, new_r
        if float(np.max(np.abs(J @ dp))) <= 1e-12 * (1.0 + np.sqrt(cost / max(L.size, 1))):
            break
    return p


def _r_factor(A: np.ndarray, block: int = 2048) -> np.ndarray:
    """Triangular factor R of ``A = Q R`` (rows of A in C order), by a tall-skinny QR: batched
    QR factorisations of row blocks, then of the stacked block factors (Q is never formed)."""
    m, u = A.shape
    if m <= 4 * block:
        return np.linalg.qr(A, mode="r")
    k = m // block
    parts = [np.linalg.qr(A[: k * block].reshape(k, block, u), mode="r").reshape(-1, u)]
    if m > k * block:
        parts.append(A[k * block:])
    return _r_factor(np.vstack(parts), block)


def _linearised_start(u: np.ndarray, X: np.ndarray, ns, what: str) -> tuple[np.ndarray, float]:
    """The lecture's linearised least squares (observations on both sides) with ``h_last = 1``
    in the *raw* coordinates.

    Solved in normalised coordinates (``u`` source, ``X`` target) as the homogeneous problem
    ``min |A h|^2`` subject to the linear constraint (raw last element) ``c.h = 1``:
    ``h = N^-1 c / (c.N^-1 c)`` with ``N = R.T R`` from a QR factorisation of ``A`` (no normal
    equations are formed); ``v.T v = 1 / (c.N^-1 c)``. Returns ``h`` (normalised, (d+1)^2) and
    ``v.T v`` in normalised target units. Used for initial values and reported as the
    linearised solution; the estimate itself is the adjustment that follows.
    """
    n, d = u.shape
    npar = (d + 1) ** 2
    A = np.zeros((n, d, npar))
    for k in range(d):
        for j in range(d):
            A[:, k, k * (d + 1) + j] = -u[:, j]
            A[:, k, d * (d + 1) + j] = X[:, k] * u[:, j]
        A[:, k, k * (d + 1) + d] = -1.0
        A[:, k, d * (d + 1) + d] = X[:, k]
    R = np.zeros((npar, npar))
    Rf = _r_factor(A.reshape(n * d, npar))[:npar]
    R[: Rf.shape[0]] = Rf  # square (zero rows when there are fewer equations than unknowns)
    sv = np.linalg.svd(R, compute_uv=False)
    if not np.all(np.isfinite(sv)) or sv[-2] <= 1e-12 * sv[0]:
        raise DegenerateGeometryError(
            f"{what}: the point configuration does not determine a projective transformation "
            "(the linearised equations are rank deficient); add points in general position"
        )
    # raw h_last = (H_n Ts)[d, d] = h_n[d, :d] . (-centre / scale) + h_n[d, d]
    cons = np.zeros(npar)
    cons[d * (d + 1):d * (d + 1) + d] = -ns.centre / ns.scale
    cons[-1] = 1.0
    if sv[-1] <= 1e-12 * sv[0]:  # an exact fit: the null vector of A, scaled to c.h = 1
        h = np.linalg.svd(R)[2][-1]
        ch = cons @ h
        if abs(ch) <= 1e-12 * np.max(np.abs(h)):
            raise DegenerateGeometryError(
                f"{what}: the exact solution maps the source origin to infinity; shift the "
                "source coordinates"
            )
        return h / ch, 0.0
    y = scipy.linalg.solve_triangular(R, cons, trans="T", check_finite=False)
    h = scipy.linalg.solve_triangular(R, y, check_finite=False) / (y @ y)
    return h, float(1.0 / (y @ y))


def _fit_projective(src, dst, obs, sigma0_prior, what, errors_in, max_iter, tol):
    n, d = src.shape
    ns, nt = normalize_points(src), normalize_points(dst)
    u = ns.apply(src)
    h_lin, vtv_lin = _linearised_start(u, nt.apply(dst), ns, what)
    ks, kt = ns.scale, nt.scale
    names = (Projective2D if d == 2 else Projective3D).names
    if abs(h_lin[-1]) <= 1e-12 * np.max(np.abs(h_lin)):
        raise DegenerateGeometryError(
            f"{what}: the linearised solution maps the centroid of the source points to "
            "infinity; the point configuration does not determine a projective transformation"
        )
    # the linearised solution in raw coordinates (what the lecture prints)
    p_lin_raw, _ = _proj_back(h_lin[:-1] / h_lin[-1], ns, nt, d)
    linear_info = {
        "parameters": dict(zip(names, (float(v) for v in p_lin_raw))),
        # raw algebraic residuals are kt times the normalised ones (the constraint fixes the
        # raw last element at 1)
        "vtv": float(vtv_lin * kt**2),
        "redundancy": int(n * d - len(names)),
        "note": "linearised least squares x = a1 x' + a2 y' + a3 - c1 x' x - c2 y' x (observations "
                "on both sides; residuals are algebraic, not coordinate residuals)",
    }
    # the adjustment works on normalised source and centred target coordinates
    nt = replace(nt, scale=1.0)
    kt = 1.0
    X = nt.apply(dst)
    p0 = _proj_forward(p_lin_raw, ns, nt, d)
    if errors_in == "target":
        w, C = _unit_weights_scaled(n, np.ones(d), obs)
        if C is None:
            p0 = _refine_start(p0, u, X, w)
        adj = gauss_markov(
            lambda p: _proj_rational(p, u)[0].reshape(-1),
            p0,
            X.reshape(-1),
            jacobian=lambda p: _proj_jacobian(p, u),
            weights=w,
            covariance=C,
            sigma0_prior=sigma0_prior,
            names=names,
            max_iter=max_iter,
            tol=tol,
            what=what,
        )
        method = "Gauss-Markov (rational form)"
        note = (
            "nonlinear Gauss-Markov adjustment of the rational projective equations (errors in "
            "the target coordinates), started from the linearised least-squares solution "
            "(extras['linearised']) refined by Gauss-Newton steps"
        )
        p_n = adj.x
        extra_res = None
    else:
        factors = np.concatenate([np.full(d, ks), np.full(d, kt)])
        w, C = _unit_weights_scaled(n, factors, obs)
        L = np.column_stack([u, X]).reshape(-1)

        def conditions(p, lk):
            lk = lk.reshape(n, 2 * d)
            Xh, wd, _ = _proj_rational(p, lk[:, :d])
            return ((lk[:, d:] - Xh) * wd[:, None]).reshape(-1)

        def jac_x(p, lk):
            lk = lk.reshape(n, 2 * d)
            uu, XX = lk[:, :d], lk[:, d:]
            J = np.zeros((n, d, p.size))
            for k in range(d):
                for j in range(d):
                    J[:, k, k * (d + 1) + j] = -uu[:, j]
                    J[:, k, d * (d + 1) + j] = XX[:, k] * uu[:, j]
                J[:, k, k * (d + 1) + d] = -1.0
            return J.reshape(n * d, -1)

        def jac_l(p, lk):
            lk = lk.reshape(n, 2 * d)
            uu, XX = lk[:, :d], lk[:, d:]
            H = np.append(p, 1.0).reshape(d + 1, d + 1)
            wd = _affine_rows(H[d:], uu)[:, 0]
            blocks = np.zeros((n, d, 2 * d))
            blocks[:, :, :d] = XX[:, :, None] * H[d, :d][None, None, :] - H[None, :d, :d]
            blocks[:, np.arange(d), d + np.arange(d)] = wd[:, None]
            if n * d < SPARSE_FROM:
                return scipy.linalg.block_diag(*blocks) if n > 0 else np.zeros((0, 0))
            return scipy.sparse.block_diag(list(blocks), format="csr")

        adj = gauss_helmert(
            conditions,
            p0,
            L,
            jacobian_x=jac_x,
            jacobian_l=jac_l,
            weights=w,
            covariance=C,
            sigma0_prior=sigma0_prior,
            names=names,
            max_iter=max_iter,
            tol=tol,
            what=what,
        )
        corr = adj.residuals.reshape(n, 2 * d) * factors
        extra_res = corr[:, :d]
        nr = adj.normalized_residuals
        rn = adj.redundancy_numbers
        adj = replace(
            adj,
            residuals=corr[:, d:].reshape(-1),
            normalized_residuals=None if nr is None else nr.reshape(n, 2 * d)[:, d:].reshape(-1),
            redundancy_numbers=None if rn is None else rn.reshape(n, 2 * d)[:, d:].reshape(-1),
        )
        extra_res = {
            "source_residuals": extra_res,
            "source_normalized_residuals": None if nr is None else nr.reshape(n, 2 * d)[:, :d],
            "source_redundancy_numbers": None if rn is None else rn.reshape(n, 2 * d)[:, :d],
        }
        method = "Gauss-Helmert (errors in source and target)"
        note = (
            "Gauss-Helmert adjustment (errors in source and target coordinates), started from "
            "the linearised least-squares solution (extras['linearised']); residuals are the "
            "target corrections, the source corrections are in extras['source_residuals']"
        )
        p_n = adj.x
    p, J = _proj_back(p_n, ns, nt, d)
    cls = Projective2D if d == 2 else Projective3D
    return cls.from_parameters(p), adj, p, J, method, note, linear_info, extra_res


# --- the 3D similarity and rigid models ----------------------------------------------------------


def _fit_absolute(model, src, dst, weights, covariance, sigma0_prior, what):
    try:
        from ..orientation.absolute import absolute_orientation
    except ImportError as exc:  # pragma: no cover - depends on the installed parts
        raise InputError(
            f"{what}: photogeom.orientation.absolute is not available in this installation"
        ) from exc
    kwargs: dict = {"method": "svd"}
    params = inspect.signature(absolute_orientation).parameters
    wanted = {"weights": weights, "covariance": covariance}
    if sigma0_prior != 1.0:
        wanted["sigma0_prior"] = sigma0_prior
    if model == "rigid3d":
        wanted["with_scale"] = False
    for key, value in wanted.items():
        if value is None:
            continue
        if key not in params:
            raise InputError(f"{what}: the absolute orientation does not accept {key!r}")
        kwargs[key] = value
    return absolute_orientation(src, dst, **kwargs)


def _helmert_extras(fit: Fit) -> dict:
    """Geodetic Helmert parameters (EPSG conventions) of a fitted 3D similarity, name ->
    (value, std): shifts in target units, rotations in arc-seconds, scale difference in ppm.

    Position-vector rotations are the ``"transposed"`` angles omega, phi, kappa, so their
    standard deviations are those of the fit; the coordinate-frame rotations are those of
    ``R.T`` (equal and opposite to first order), with the same standard deviations.
    """
    m = fit.model
    if not isinstance(m, Similarity3D) or not m.check:
        return {}
    std = fit.std_errors
    sec = 180.0 / np.pi * 3600.0
    sd = {
        "tx": std.get("tx", np.nan), "ty": std.get("ty", np.nan), "tz": std.get("tz", np.nan),
        "rx": std.get("omega", np.nan) * sec, "ry": std.get("phi", np.nan) * sec,
        "rz": std.get("kappa", np.nan) * sec, "ds": std.get("scale", np.nan) * 1e6,
    }
    out: dict = {}
    for conv in ("position_vector", "coordinate_frame"):
        hp = m.helmert_parameters(conv)
        out[conv] = {k: (float(hp[k]), float(sd[k])) for k in hp}
    out["units"] = {"tx": "m", "ty": "m", "tz": "m", "rx": "arcsec", "ry": "arcsec",
                    "rz": "arcsec", "ds": "ppm"}
    return out


# --- public entry point --------------------------------------------------------------------------


def _textbook(model, cofactor: np.ndarray, sigma0: float):
    """Textbook parameters with standard deviations: name -> (value, std)."""
    tb = model.textbook()
    Jt = model.textbook_jacobian()
    Q = Jt @ cofactor @ Jt.T
    std = np.sqrt(np.clip(np.diag(Q), 0.0, None)) * sigma0
    return {n: (float(v), float(s)) for (n, v), s in zip(tb.items(), std)}, Q


def estimate_transform(
    model: str,
    source,
    target,
    *,
    order: int | None = None,
    weights=None,
    check=None,
    ids=None,
    covariance=None,
    sigma0_prior: float = 1.0,
    source_system: str | None = None,
    target_system: str | None = None,
    errors_in: str = "target",
    unit: str = "",
    max_iter: int = 50,
    tol: float = 1e-10,
) -> Fit:
    """Estimate a transformation ``target = T(source)`` from point pairs by least squares.

    Parameters
    ----------
    model : str
        One of ``"similarity2d"``, ``"affine2d"``, ``"projective2d"``, ``"polynomial2d"``,
        ``"rigid3d"``, ``"similarity3d"``, ``"affine3d"``, ``"projective3d"``,
        ``"polynomial3d"``.
    source, target : array_like, shape (n, 2) or (n, 3)
        Corresponding points (control and check points), in source and target units.
    order : int, optional
        Polynomial order (polynomial models only; required there).
    weights : array_like, optional
        Per point (n,) or per coordinate (n, d); with ``errors_in="both"`` per coordinate
        (n, 2 d) with source coordinates first. Weight 1 means standard deviation
        ``sigma0_prior``.
    check : array_like of bool, shape (n,), optional
        ``True`` marks check points: they do not enter the estimate and their residuals
        (computed minus observed) are reported in ``fit.check_residuals``.
    ids : sequence, optional
        Point ids (default 1..n), used to label residual rows.
    covariance : array_like, optional
        Observation covariance, per point (n, d, d) (``(n, 2d, 2d)`` with errors in both) or
        full (n d, n d), observations point by point; in target units squared.
    sigma0_prior : float
        A-priori standard deviation of unit weight.
    source_system, target_system : str, optional
        Names of the 2D systems (``"pixel"``, ``"image"``, ``"fiducial"``, ...; see
        :mod:`photogeom.imagecoords`). A left-handed system paired with a right-handed one has
        its row/y coordinate negated before the fit (noted in ``fit.notes`` and
        ``fit.extras["handedness"]``); the fitted transformation works on the flipped
        coordinates, residuals are reported in the target system as given.
    errors_in : {"target", "both"}
        Projective models only: ``"target"`` - nonlinear Gauss-Markov with errors in the target
        coordinates; ``"both"`` - Gauss-Helmert with errors in source and target.
    unit : str
        Unit of the target coordinates, used to label residuals and shifts (e.g. ``"mm"``).
    max_iter, tol : int, float
        Iteration limit and tolerance of the nonlinear adjustments (projective models).

    Returns
    -------
    Fit
        ``fit.model`` the fitted transformation; ``fit.parameters`` in the parametric form with
        covariance; ``fit.extras["textbook"]``: textbook parameters ``name -> (value, std)``
        (angles in radians) by first-order error propagation of the parametric covariance
        (a-posteriori sigma0); projective fits also carry ``extras["linearised"]``.

    Raises
    ------
    TooFewPointsError
        Fewer control points than the model needs (the message names the minimum).
    DegenerateGeometryError
        Coincident, collinear or coplanar points where the model needs more.
    InputError
        Shapes, NaN / infinite values, unknown model or options.
    """
    t0 = time.perf_counter()
    key = str(model).strip().lower()
    if key not in MODELS:
        raise InputError(f"unknown transformation model {model!r}; use one of {', '.join(MODELS)}")
    d = MODELS[key]
    what = key
    if key.startswith("polynomial"):
        if order is None:
            raise InputError(f"{key}: give the polynomial order (order=1, 2, 3, ...)")
        if int(order) != order or order < 1:
            raise InputError(f"{key}: order must be an integer >= 1, got {order!r}")
        order = int(order)
        what = f"{key} of order {order}"
    elif order is not None:
        raise InputError(f"order applies only to polynomial models, not to {key}")
    if errors_in not in ("target", "both"):
        raise InputError(f"errors_in must be 'target' or 'both', not {errors_in!r}")
    if errors_in == "both" and not key.startswith("projective"):
        raise InputError(
            f"errors_in='both' is offered for the projective models; {key} is estimated with "
            "errors in the target coordinates"
        )
    src = as_points(source, d, "source", allow_single=False)
    dst = as_points(target, d, "target", allow_single=False)
    check_same_length(src, dst, "source", "target")
    n = src.shape[0]
    point_ids = _ids(ids, n)
    is_check = _check_mask(check, n)
    ctrl = ~is_check
    nobs = 2 * d if errors_in == "both" else d
    obs = _stochastic_model(weights, covariance, n, nobs, ctrl)
    if not (np.isfinite(sigma0_prior) and sigma0_prior > 0):
        raise InputError(f"sigma0_prior must be a positive number, got {sigma0_prior!r}")

    notes: list[str] = []
    extras: dict = {}
    plan = None
    if d == 2:
        plan = handedness_plan(source_system, target_system)
        if plan.flip_source or plan.flip_target:
            src, dst = plan.apply(src, dst)
            signs = np.ones(nobs)
            if plan.flip_source and errors_in == "both":
                signs[1] = -1.0
            if plan.flip_target:
                signs[nobs - 1] = -1.0
            obs = _flip_stochastic(obs, signs)
            notes.append(plan.note)
        extras["handedness"] = {
            "source_system": plan.source_system,
            "target_system": plan.target_system,
            "source_flip_y": plan.flip_source,
            "target_flip_y": plan.flip_target,
        }
    elif source_system is not None or target_system is not None:
        raise InputError("source_system / target_system apply to 2D models only")

    need = _min_points(key, order)
    sc, dc = src[ctrl], dst[ctrl]
    check_count(sc.shape[0], need, what, _hint(key, order) + (
        f"; {int(is_check.sum())} point(s) are check points" if is_check.any() else ""))
    _validate_geometry(key, sc, dc, need)

    ctrl_ids = _select_ids(point_ids, ctrl, numbered=bool(is_check.any()))
    labels = ("x", "y") if d == 2 else ("x", "y", "z")
    if key in ("similarity3d", "rigid3d"):
        w_ctrl = None if weights is None else np.asarray(weights, dtype=float)[ctrl]
        fit = _fit_absolute(key, sc, dc, w_ctrl, obs.covariance, sigma0_prior, what)
        if key == "rigid3d" and not isinstance(fit.model, Rigid3D):
            m = fit.model
            fit = replace(fit, model=Rigid3D(m.rotation, m.translation))
        extras.update(fit.extras or {})
        if key == "similarity3d":
            extras["helmert"] = _helmert_extras(fit)
        fit = replace(fit, ids=ctrl_ids if ctrl_ids is not None else fit.ids,
                      residual_unit=unit or fit.residual_unit,
                      residual_labels=fit.residual_labels or labels)
    else:
        if key == "similarity2d":
            tf, adj, p, J = _fit_similarity2d(sc, dc, obs, sigma0_prior, what)
            method = _METHOD_LINEAR
        elif key in ("affine2d", "affine3d"):
            tf, adj, p, J = _fit_affine(sc, dc, obs, sigma0_prior, what)
            method = _METHOD_LINEAR
        elif key.startswith("polynomial"):
            tf, adj, p, J = _fit_polynomial(sc, dc, order, obs, sigma0_prior, what)
            method = _METHOD_LINEAR
            centre = np.array2string(tf.centre, precision=6)
            notes.append(
                f"coefficients refer to reduced source coordinates (x - {centre}) / "
                f"{tf.scale:.6g}; extras['textbook'] holds the plain coefficients"
            )
        else:
            tf, adj, p, J, method, note, lin, extra_res = _fit_projective(
                sc, dc, obs, sigma0_prior, what, errors_in, max_iter, tol)
            notes.append(note)
            extras["linearised"] = lin
            if extra_res is not None:
                extras.update(extra_res)
        tb_units = tf.textbook_units
        units = dict.fromkeys(tf.parameter_names, "")
        if key in ("similarity2d", "affine2d", "affine3d"):
            units = dict.fromkeys(tf.parameter_names, "1")
            shifts = {"similarity2d": ("c", "d"), "affine2d": ("a3", "b3"),
                      "affine3d": ("tx", "ty", "tz")}[key]
            units.update(dict.fromkeys(shifts, unit))
        fit = Fit.from_adjustment(
            adj, tf, method, point_dim=d, parameters=p, parameter_names=tf.parameter_names,
            jacobian=J, ids=ctrl_ids, residual_labels=labels, residual_unit=unit,
            parameter_units=units,
        )
        textbook, Qtb = _textbook(tf, fit.cofactor, fit.sigma0)
        extras["textbook"] = textbook
        extras["textbook_units"] = {k: (unit if v == "" else v) for k, v in tb_units.items()}
        extras["textbook_cofactor"] = Qtb

    # residuals back in the systems as given (undo the flips)
    if plan is not None and plan.flip_source:
        for name in ("source_residuals", "source_normalized_residuals"):
            if extras.get(name) is not None:
                extras[name] = extras[name] * np.array([1.0, -1.0])
    if plan is not None and plan.flip_target:
        sign = np.array([1.0, -1.0])
        nr = fit.normalized_residuals
        fit = replace(fit, residuals=fit.residuals * sign,
                      normalized_residuals=None if nr is None else nr * sign)
    if is_check.any():
        chk = fit.model.apply(src[is_check]) - dst[is_check]
        if plan is not None and plan.flip_target:
            chk = chk * np.array([1.0, -1.0])
        fit = fit.with_checks(chk, _select_ids(point_ids, is_check, numbered=True))
    return replace(fit, notes=tuple(fit.notes) + tuple(notes), extras=extras,
                   elapsed=time.perf_counter() - t0)
