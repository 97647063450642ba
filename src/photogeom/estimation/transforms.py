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

import functools
import itertools
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg
import scipy.linalg.lapack as _lapack

from ..adjust import (
    Adjustment,
    Fit,
    PointNormalization,
    gauss_helmert,
    gauss_markov,
    normalize_points,
    solve_linear,
)
from ..adjust.gauss_markov import NORMAL_FROM, r_factor
from ..adjust.result import BareSolution
from ..errors import DegenerateGeometryError, InputError
from ..imagecoords import handedness_plan
from ..records import read_only_view
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
from ..validation import (
    as_points,
    check_count,
    check_finite,
    check_finite_magnitude,
    check_same_length,
)
from .rational_projective import (
    RationalModel,
    affine_rows,
    gauss_newton_unit,
    homogeneous_matrix,
    homogeneous_points,
    rational_map,
)

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
#: Largest number of points of a projective fit without statistics that takes the
#: model-specific Gauss-Newton path (:mod:`.rational_projective`); beyond it the general
#: engine's column-wise Jacobian and normal-equation solver are faster (measured crossover
#: between 5e3 and 1e5 points).
LEAN_MAX_POINTS = 4096

#: Relative size of the smallest singular value of the centred points below which the points
#: are treated as collinear / coplanar.
RANK_TOLERANCE = 1e-10

_METHOD_LINEAR = "linear least squares (QR)"

_EPS = float(np.finfo(float).eps)


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


_NO_OBSERVATION_MODEL = _Observations(None, None)


def _stochastic_model(
    weights, covariance, n: int, k: int, mask: np.ndarray | None
) -> _Observations:
    """Weights (n,) or (n, k), or covariance (n, k, k) or (n k, n k), restricted to ``mask``
    (None: all points)."""
    if weights is None and covariance is None:
        return _NO_OBSERVATION_MODEL
    if mask is None:
        mask = np.ones(n, dtype=bool)
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


def _unit_weights_scaled(n: int, factors: np.ndarray | None, obs: _Observations):
    """Engine weights/covariance for normalised observations (observation / factor;
    ``factors`` None: all 1)."""
    if factors is None:
        if obs.covariance is None and obs.weights is None:
            return None, None
        factors = np.ones(obs.weights.shape[1] if obs.weights is not None else 1)
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


def _select_ids(ids: np.ndarray | None, mask: np.ndarray | None, numbered: bool) -> tuple | None:
    """Ids of the rows in ``mask`` (None: all rows; row numbers 1..n when no ids were given
    and ``numbered``; None when no ids were given and all rows are selected)."""
    if ids is None:
        if not numbered:
            return None
        return tuple((np.flatnonzero(mask) + 1).tolist())
    return tuple((ids if mask is None else ids[mask]).tolist())


def _check_mask(check, n: int) -> np.ndarray | None:
    """Boolean mask of the check points, or None when there are none."""
    if check is None:
        return None
    c = np.asarray(check)
    if c.shape != (n,):
        raise InputError(f"check: expected a boolean mask of shape ({n},), got shape {c.shape}")
    if c.dtype != bool:
        if not np.all(np.isin(c, (0, 1))):
            raise InputError("check: expected a boolean mask (True marks a check point)")
        c = c.astype(bool)
    return c if c.any() else None


_MIN_POINTS = {
    "similarity2d": 2,
    "affine2d": 3,
    "projective2d": 4,
    "rigid3d": 3,
    "similarity3d": 3,
    "affine3d": 4,
    "projective3d": 5,
}


def _min_points(model: str, order: int | None) -> int:
    return _MIN_POINTS.get(model) or polynomial_term_count(order, MODELS[model])


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


def _centred(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid and centred copy of points (n, d). Many points: the sums as one matrix-vector
    product and the centring column by column (numpy's axis-0 reductions and row-wise
    broadcasting over 2 or 3 columns are several times slower)."""
    n, d = points.shape
    if n <= 4096:
        centre = np.add.reduce(points, axis=0) / n
        return centre, points - centre
    centre = (np.ones(n) @ points) / n
    c = np.empty((n, d))
    for k in range(d):
        np.subtract(points[:, k], centre[k], out=c[:, k])
    return centre, c


def _rank(points: np.ndarray) -> tuple[int, np.ndarray]:
    """Numerical rank of the centred point set (0 = all coincide) and its singular values."""
    _, c = _centred(points)
    mag = max(float(max(points.max(), -points.min())), 1e-300)
    if float(max(c.max(), -c.min())) <= 1e-13 * mag:
        return 0, np.zeros(points.shape[1])
    if c.shape[0] <= 5000:
        s = np.linalg.svd(c, compute_uv=False)
    else:  # many points: the scatter matrix, and a QR only when that is ambiguous
        ev = np.linalg.eigvalsh(c.T @ c)
        s = np.sqrt(np.clip(ev[::-1], 0.0, None))
        if s[-1] <= 1e-6 * s[0]:
            s = np.linalg.svd(np.linalg.qr(c, mode="r"), compute_uv=False)
    return int(np.sum(s > RANK_TOLERANCE * s[0])), s


def _spread_certified(points: np.ndarray, need_rank: int) -> bool:
    """True when the rule of :func:`_rank` certainly gives at least ``need_rank``, decided
    cheaply from the 2x2 / 3x3 scatter of the centred points (invariants of its eigenvalues
    ``l1 >= l2 >= l3``: ``l2 / l1 >= e2 / (3 e1^2)``, ``l_d / l1 >= det / (e1 e_{d-1})``,
    with margins far above their rounding errors and far below the rule's ``1e-20``);
    False means: not proven, decide exactly."""
    n, d = points.shape
    c = points - np.add.reduce(points, axis=0) / n
    return _scatter_certified((c.T @ c).tolist(), n, d, need_rank)


def _scatter_certified(S: list, n: int, d: int, need_rank: int, k: int = 0) -> bool:
    """:func:`_spread_certified` from the scatter matrix of n centred points: the d x d block
    of ``S`` (nested lists) that starts at row and column ``k``."""
    a, b = S[k], S[k + 1]
    s00, s01, s11 = a[k], a[k + 1], b[k + 1]
    if d == 2:
        e1 = s00 + s11
    else:
        c = S[k + 2]
        s02, s12, s22 = a[k + 2], b[k + 2], c[k + 2]
        e1 = s00 + s11 + s22
    if not (e1 > 0 and math.isfinite(e1)):
        return False
    # rounding of the n-term sums and of the invariants: relative to e1^k at most ~n eps
    thr = max(3e-13, 16 * n * _EPS)
    if d == 2:  # S is symmetric: S[1][0] = S[0][1]
        return need_rank <= 1 or s00 * s11 - s01 * s01 > thr * e1 * e1
    e2 = s00 * s11 - s01 * s01 + s00 * s22 - s02 * s02 + s11 * s22 - s12 * s12
    if need_rank <= 2:
        return need_rank <= 1 or e2 > thr * e1 * e1
    det = (s00 * (s11 * s22 - s12 * s12) - s01 * (s01 * s22 - s12 * s02)
           + s02 * (s01 * s12 - s11 * s02))
    return det > 1e-14 * e1 * e2 and det > thr * e1 * e1 * e1


@dataclass(frozen=True, slots=True)
class _CentredPair:
    """Source and target points centred together (one pass for the geometry check and the
    normalisation of the projective fits)."""

    centre: np.ndarray  # (2 d,): source centroid, then target centroid
    centred: np.ndarray  # (n, 2 d): centred source, then centred target coordinates
    scatter: list  # (2 d) x (2 d) nested lists: centred.T @ centred

    @classmethod
    def of(cls, src: np.ndarray, dst: np.ndarray) -> _CentredPair | None:
        """The centred pair, or None when a coordinate sum is not finite (NaN or infinite
        values, or an overflow: the caller checks the values)."""
        n = src.shape[0]
        Z = np.concatenate((src, dst), axis=1)
        sums = np.add.reduce(Z, axis=0)
        if not math.isfinite(sum(sums.tolist())):
            return None
        mu = sums / n
        Z -= mu
        return cls(mu, Z, (Z.T @ Z).tolist())

    def normalization(self, side: int, d: int) -> PointNormalization:
        """:func:`_normalised` of the source (side 0) or target (side 1) from the scatter."""
        k = side * d
        S = self.scatter
        ss = S[k][k] + S[k + 1][k + 1] + (S[k + 2][k + 2] if d == 3 else 0.0)
        return PointNormalization(self.centre[k:k + d], _rms_scale(ss, self.centred.shape[0] * d))

    def certified(self, need_rank: int) -> bool:
        """:func:`_spread_certified` of both point sets."""
        S = self.scatter
        n = self.centred.shape[0]
        d = len(S) // 2
        return _scatter_certified(S, n, d, need_rank) and _scatter_certified(
            S, n, d, need_rank, d
        )


def _geometry(points: np.ndarray, need_rank: int, model: str, side: str, need: int) -> None:
    """Raise :class:`DegenerateGeometryError` when the points span fewer dimensions."""
    if points.shape[0] <= 5000 and need_rank >= 2 and _spread_certified(points, need_rank):
        return
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


def _validate_geometry(
    model: str, src: np.ndarray, dst: np.ndarray, need: int
) -> _CentredPair | None:
    """Raise when the points cannot determine the model; for the models with conditions on
    both sides return the centred pair the check computed (None for many points or other
    models). For those models the values need not have been checked for NaN / infinity:
    a finite scatter proves them finite, and otherwise they are checked here first."""
    d = src.shape[1]
    pair = None
    if model == "similarity2d":
        _geometry(src, 1, model, "source", need)
    elif model in ("affine2d", "affine3d", "polynomial2d", "polynomial3d"):
        _geometry(src, d, model, "source", need)
    else:  # rigid3d, similarity3d (a plane is enough), projective2d/3d: both sides spread
        need_rank = 2 if model in ("rigid3d", "similarity3d") else d
        if src.shape[0] <= 5000:  # the exact rank check takes over for more points
            pair = _CentredPair.of(src, dst)
        if pair is None or not pair.certified(need_rank):
            # not proven from a finite scatter: the values first (the caller may have left
            # their check to this function), then the exact rank
            check_finite(src, "source")
            check_finite(dst, "target")
            _geometry(src, need_rank, model, "source", need)
            _geometry(dst, need_rank, model, "target", need)
        if model.startswith("projective") and src.shape[0] == need:
            _general_position(src, model, "source")
            _general_position(dst, model, "target")
    return pair


# --- combination of per-coordinate adjustments ---------------------------------------------------


def _combine(parts: list[Adjustment], names: tuple[str, ...]) -> Adjustment:
    """One Adjustment from independent per-coordinate adjustments of the same points
    (observations interleaved point by point, parameters concatenated)."""

    def stack(attr):
        vals = [getattr(a, attr) for a in parts]
        if any(v is None for v in vals):
            return None
        if vals[0].size == 0:  # statistics=False
            return vals[0]
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
    statistics: bool = True,
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
                                      names=names[j * m:(j + 1) * m], what=what,
                                      statistics=statistics, check_finite=False))
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
        statistics=statistics,
        check_finite=False,
    )


# --- the linear models -------------------------------------------------------------------------


def _fit_similarity2d(src, dst, obs, sigma0_prior, what, statistics=True):
    ns, u = _normalised(src)
    ct, X = _centred(dst)
    n = src.shape[0]
    A = np.zeros((n, 2, 4))
    A[:, 0, 0], A[:, 0, 1], A[:, 0, 2] = u[:, 0], u[:, 1], 1.0
    A[:, 1, 0], A[:, 1, 1], A[:, 1, 3] = u[:, 1], -u[:, 0], 1.0
    adj = solve_linear(A.reshape(2 * n, 4), X.reshape(-1), weights=obs.flat_weights(),
                       covariance=obs.covariance, sigma0_prior=sigma0_prior,
                       names=("a", "b", "c", "d"), what=what, statistics=statistics,
                       check_finite=False)
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


#: Names of the normalised affine unknowns, d = 2, 3 (one row of parameters per coordinate).
_AFFINE_NAMES = {d: tuple(f"{r}{j}" for r in "abc"[:d] for j in range(1, d + 2)) for d in (2, 3)}


def _fit_affine(src, dst, obs, sigma0_prior, what, force=None, statistics=True):
    d = src.shape[1]
    ns, u = _normalised(src)
    ct, L = _centred(dst)
    D = np.empty((src.shape[0], d + 1))
    D[:, :d] = u
    D[:, d] = 1.0
    adj = _shared_design_solve(D, L, obs, sigma0_prior, _AFFINE_NAMES[d], what, force,
                               statistics)
    Jr = _affine_back(ns, ct, d)
    xr = adj.x.reshape(d, d + 1)
    rows = xr @ Jr.T  # per output row [a.., t]
    rows[:, d] += ct
    Jrows = None
    if statistics:  # block diagonal, row-block order (a1 a2 a3 b1 b2 b3 ...)
        m = d + 1
        Jrows = np.zeros((d * m, d * m))
        for r in range(d):
            Jrows[r * m:(r + 1) * m, r * m:(r + 1) * m] = Jr
    if d == 2:
        p = rows.reshape(-1)
        return Affine2D(*p), adj, p, Jrows
    # Affine3D parameter order: a11..a33, tx, ty, tz
    perm = [r * 4 + j for r in range(3) for j in range(3)] + [3, 7, 11]
    p = rows.reshape(-1)[perm]
    return Affine3D(rows[:, :3], rows[:, 3]), adj, p, None if Jrows is None else Jrows[perm]


def _fit_polynomial(src, dst, order, obs, sigma0_prior, what, force=None, statistics=True):
    d = src.shape[1]
    ns, u = _normalised(src)
    ct, L = _centred(dst)
    exps = polynomial_exponents(order, d)
    D = polynomial_terms(u, exps)
    cls = Polynomial2D if d == 2 else Polynomial3D
    template = cls(order, np.zeros((d, exps.shape[0])), ns.centre, ns.scale)
    names = template.parameter_names
    adj = _shared_design_solve(D, L, obs, sigma0_prior, names, what, force, statistics)
    C = adj.x.reshape(d, -1).copy()
    C[:, 0] += ct  # the constant monomial is first
    model = cls(order, C, ns.centre, ns.scale)
    return model, adj, model.parameters, None


# --- projective models -------------------------------------------------------------------------


def _rms_scale(sum_squares: float, count: int) -> float:
    """Scale of :func:`normalize_points` from the sum of squares of ``count`` centred
    coordinates: their RMS, or 1 when that is zero or not finite (all points coincide)."""
    rms = math.sqrt(sum_squares / count)
    return rms if math.isfinite(rms) and rms > 0.0 else 1.0


def _normalised(points: np.ndarray, scaled: bool = True):
    """:func:`normalize_points` of ``points`` and the normalised (``scaled``) or only
    centred points, from one centring."""
    n, dim = points.shape
    centre, c = _centred(points)
    rms = _rms_scale(float(np.vdot(c, c)), n * dim)
    if scaled:
        c *= 1.0 / rms
    return PointNormalization(centre, rms), c


def _projective(h: list, d: int):
    """``Projective2D/3D`` of the row-major elements ``h`` (a list, already normalised to
    ``h[-1] = 1``): the same object as the constructor gives, without repeating its
    normalisation (its checks are done here)."""
    if not all(map(math.isfinite, h)):
        raise DegenerateGeometryError(
            "projective: the estimated transformation has non-finite elements; the point "
            "configuration does not determine it"
        )
    H = np.array(h).reshape(d + 1, d + 1)
    H.flags.writeable = False
    tf = object.__new__(Projective2D if d == 2 else Projective3D)
    object.__setattr__(tf, "matrix", H)
    return tf


def _proj_back(
    p_n: np.ndarray, ns, nt, d: int, jacobian: bool = True
) -> tuple[object, np.ndarray, np.ndarray | None]:
    """The transformation, its raw parameters and d p_raw / d p_n (None unless ``jacobian``)
    from normalised ones: H = Tt^-1 H_n Ts / h_last."""
    m = d + 1
    hn = p_n.tolist()
    hn.append(1.0)
    ks, cs = float(ns.scale), ns.centre.tolist()
    kt, ct = float(nt.scale), nt.centre.tolist()
    # H_n Ts with Ts = [[I / ks, -cs / ks], [0, 1]], then Tt^-1 = [[kt I, ct], [0, 1]] on the
    # left (scalar arithmetic: (d+1)^2 elements, plain loops: no per-row generator frames)
    rows = []
    for i in range(m):
        r = hn[i * m:(i + 1) * m]
        t = r[d]
        for j in range(d):
            r[j] = r[j] / ks
            t -= r[j] * cs[j]
        r[d] = t
        rows.append(r)
    bottom = rows[d]
    h = []
    for i in range(d):
        r, c = rows[i], ct[i]
        for j in range(m):
            h.append(kt * r[j] + c * bottom[j])
    h += bottom
    last = h[-1]
    if abs(last) <= 1e-14 * max(map(abs, h)):
        raise _origin_at_infinity(np.array(h), "projective")
    h = [v / last for v in h]
    tf = _projective(h, d)
    p = np.array(h[:-1])
    if not jacobian:
        return tf, p, None
    Tt_inv = np.eye(d + 1)
    Tt_inv[:d, :d] *= nt.scale
    Tt_inv[:d, d] = nt.centre
    K = np.kron(Tt_inv, ns.matrix.T)  # vec_row(Tt^-1 H Ts) = K vec_row(H)
    Kf = K[:, :-1]  # the last normalised element is fixed at 1
    J = (Kf[:-1] - np.outer(p, Kf[-1])) / last
    return tf, p, J


def _linearised_start(
    u1: np.ndarray, X: np.ndarray, ns, what: str, reweight: bool = False
) -> tuple[np.ndarray, float, np.ndarray]:
    """The lecture's linearised least squares (observations on both sides) with ``h_last = 1``
    in the *raw* coordinates, and the start of the adjustment.

    Solved in normalised coordinates (``u1 = [u, 1]`` of the normalised source points ``u``,
    ``X`` target) as the homogeneous problem
    ``min |A h|^2`` subject to the linear constraint (raw last element) ``c.h = 1``:
    ``h = N^-1 c / (c.N^-1 c)`` with ``N = R.T R`` from a QR factorisation of ``A`` (no normal
    equations are formed); ``v.T v = 1 / (c.N^-1 c)``. Used for initial values and reported
    as the linearised solution; the estimate itself is the adjustment that follows.

    Returns ``h`` (normalised, (d+1)^2), its ``v.T v`` in normalised target units, and the
    start: with ``reweight``, the same equations solved again with those of each point
    multiplied by ``1 / w_i`` (the denominator at ``h``), which turns the algebraic residuals
    into first-order coordinate residuals (a start closer to the adjustment); otherwise, or
    when a denominator nearly vanishes, ``h`` itself.
    """
    n, m = u1.shape
    d = m - 1
    npar = m * m
    u = u1[:, :d]
    # raw h_last = (H_n Ts)[d, d] = h_n[d, :d] . (-centre / scale) + h_n[d, d]
    ks = float(ns.scale)
    cons = np.array([0.0] * (d * m) + [-c / ks for c in ns.centre.tolist()] + [1.0])
    A = None
    out = _linearised_normal(u, X, cons, None) if n * d >= NORMAL_FROM else None
    if out is None:
        A = _linearised_design(u1, X)
        out = _constrained_null_vector(A.reshape(n * d, npar), cons, what)
    h, vtv = out
    hl = h.tolist()
    if abs(hl[-1]) <= 1e-12 * max(map(abs, hl)):
        raise DegenerateGeometryError(
            f"{what}: the linearised solution maps the centroid of the source points to "
            "infinity; the point configuration does not determine a projective transformation"
        )
    if not reweight:
        return h, vtv, h
    wl = u1 @ h[d * m:]
    awl = np.abs(wl)
    if not awl.min() > 1e-6 * awl.max():
        return h, vtv, h
    row_scale = 1.0 / wl
    out = _linearised_normal(u, X, cons, row_scale) if A is None else None
    if out is None:
        if A is None:
            A = _linearised_design(u1, X)
        A *= row_scale[:, None, None]
        out = _constrained_null_vector(A.reshape(n * d, npar), cons, what)
    return h, vtv, out[0]


def _origin_at_infinity(h: np.ndarray, what: str) -> DegenerateGeometryError:
    """The error for a projective solution ``h`` (the (d+1)^2 matrix elements) whose last
    element is zero: it sends the source origin to infinity.

    A regular matrix is a genuine transformation that does so: shifting the source
    coordinates lets it be written with its last element 1. A singular one is no
    transformation at all (it collapses the source space): the points do not determine
    one, as when all but one lie on a line (2D) or all but a few in a plane (3D) while
    their targets do not; no shift helps.
    """
    m = round(math.sqrt(h.size))
    sv = np.linalg.svd(np.asarray(h, dtype=float).reshape(m, m), compute_uv=False)
    if not np.all(np.isfinite(sv)) or sv[-1] <= 1e-10 * sv[0]:
        return DegenerateGeometryError(
            f"{what}: the point configuration does not determine a projective transformation: "
            "the only exact solution of the linearised equations is a singular matrix "
            "(the source points are not in general position, e.g. all but one on one line "
            "while their targets are not); add points in general position"
        )
    return DegenerateGeometryError(
        f"{what}: the solution maps the source origin to infinity, so it cannot be written "
        "with its last element 1; shift the source coordinates (e.g. subtract their mean)"
    )


def _linearised_design(u1: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Design (n, d, (d+1)^2) of the linearised equations: for coordinate k of a point,
    ``-[u, 1]`` in block k and ``X_k [u, 1]`` in the last block (``u1 = [u, 1]``)."""
    n, m = u1.shape
    d = m - 1
    A = np.zeros((n, d, m * m))
    neg = -u1
    for k in range(d):
        A[:, k, k * m:(k + 1) * m] = neg
    np.multiply(X[:, :, None], u1[:, None, :], out=A[:, :, d * m:])
    return A


def _constrained_null_vector(
    A: np.ndarray, cons: np.ndarray, what: str
) -> tuple[np.ndarray, float]:
    """``min |A h|^2`` subject to ``cons.h = 1`` and its ``|A h|^2``, from a QR factorisation
    of ``A`` (m x p); raises when ``A`` has a null space of more than one dimension."""
    m, npar = A.shape
    Rf = None
    if m >= npar:
        qr, _tau, _work, info = _lapack.dgeqrf(A)
        if info == 0:
            R = qr[:npar]  # upper triangle: R (LAPACK reads only that part below)
            # LAPACK's estimate of cond_1(R) far below 1e12 (a margin of 100 for the
            # estimate) passes both rank checks below: no SVD needed
            rcond, info = _lapack.dtrcon(R)
            if info == 0 and rcond > 1e-10:
                y, _ = _lapack.dtrtrs(R, cons, trans=1)  # R.T y = c
                h, _ = _lapack.dtrtrs(R, y)
                yy = float(y @ y)
                return h / yy, 1.0 / yy
            Rf = np.triu(R)
    if Rf is None:
        Rf = r_factor(A)
    R = np.zeros((npar, npar))
    R[: Rf.shape[0]] = Rf  # square (zero rows when there are fewer equations than unknowns)
    sv = np.linalg.svd(R, compute_uv=False)
    if not np.all(np.isfinite(sv)) or sv[-2] <= 1e-12 * sv[0]:
        raise DegenerateGeometryError(
            f"{what}: the point configuration does not determine a projective transformation "
            "(the linearised equations are rank deficient); add points in general position"
        )
    if sv[-1] <= 1e-12 * sv[0]:  # an exact fit: the null vector of A, scaled to c.h = 1
        h = np.linalg.svd(R)[2][-1]
        ch = cons @ h
        if abs(ch) <= 1e-12 * np.max(np.abs(h)):
            raise _origin_at_infinity(h, what)
        return h / ch, 0.0
    y = scipy.linalg.solve_triangular(R, cons, trans="T", check_finite=False)
    h = scipy.linalg.solve_triangular(R, y, check_finite=False) / (y @ y)
    return h, float(1.0 / (y @ y))


def _linearised_normal(u, X, cons, row_scale):
    """The solution of :func:`_linearised_start` from its normal equations ``N = A.T A``,
    assembled from weighted moments of ``z = [u, 1]`` (no (n d, (d+1)^2) design is formed):
    the equations of coordinate k are ``-z`` in block k and ``X_k z`` in the last block, so
    ``N`` has blocks ``sum z z.T`` (diagonal), ``-sum X_k z z.T`` (last column) and
    ``sum |X|^2 z z.T`` (corner).

    ``N`` of the homogeneous problem is nearly singular by design (its smallest eigenvalue
    is the algebraic misfit), so it is solved by its eigen-decomposition: the constrained
    minimum ``h = N^-1 c / (c.N^-1 c)`` is accurate when the smallest eigenvalue stands
    clear of the rounding level (``> 1e3 eps`` of the largest) and the second smallest is
    well separated (``> 1e-8``; the rank check of the QR path passes then too). Otherwise
    None: the caller factorises the design by QR.
    """
    n, d = u.shape
    m = d + 1
    # products z_a z_b (a <= b) as columns, and the factors 1, X_1 .. X_d, |X|^2
    pairs = [(a, b) for a in range(m) for b in range(a, m)]
    P = np.empty((n, len(pairs)), order="F")  # column writes contiguous
    for j, (a, b) in enumerate(pairs):
        if a == d:
            P[:, j] = 1.0
        elif b == d:
            P[:, j] = u[:, a]
        else:
            np.multiply(u[:, a], u[:, b], out=P[:, j])
    if row_scale is not None:
        P *= (row_scale * row_scale)[:, None]
    F = np.empty((n, d + 2), order="F")
    F[:, 0] = 1.0
    F[:, 1:d + 1] = X
    F[:, d + 1] = np.einsum("ij,ij->i", X, X)
    S = P.T @ F  # (pairs, d + 2)
    M = np.empty((d + 2, m, m))
    for j, (a, b) in enumerate(pairs):
        M[:, a, b] = M[:, b, a] = S[j]
    npar = m * m
    N = np.zeros((npar, npar))
    last = slice(d * m, npar)
    for k in range(d):
        blk = slice(k * m, (k + 1) * m)
        N[blk, blk] = M[0]
        N[blk, last] = -M[k + 1]
        N[last, blk] = -M[k + 1]
    N[last, last] = M[d + 1]
    lam, V = np.linalg.eigh(N)
    top = lam[-1]
    if not (math.isfinite(top) and lam[0] > 1e3 * _EPS * top and lam[1] > 1e-8 * top):
        return None
    g = (V.T @ cons) / lam  # N^-1 c in the eigenbasis
    h = (V @ g) / float(g @ (V.T @ cons))
    # v.T v = |A h|^2 from the equations themselves (the smallest eigenvalue of N carries
    # only eps cond(N) relative accuracy)
    Gz = affine_rows(h.reshape(m, m), u)  # rows z.h_k, k = 0..d
    r = Gz[:, d:] * X - Gz[:, :d]
    if row_scale is not None:
        r *= row_scale[:, None]
    return h, float(np.vdot(r, r))


_NOTE_RATIONAL = (
    "nonlinear Gauss-Markov adjustment of the rational projective equations (errors in "
    "the target coordinates), started from the linearised least-squares solution "
    "(extras['linearised'])"
)


def _fit_projective(src, dst, obs, sigma0_prior, what, errors_in, max_iter, tol,
                    statistics=True, pair: _CentredPair | None = None):
    n, d = src.shape
    if pair is None:
        ns, u = _normalised(src)
        nt, X = _normalised(dst, scaled=False)  # the adjustment works on the centred target
        u1 = homogeneous_points(u)
    else:  # the same, from the centring of the geometry check, written into [u, 1] at once
        ns, nt = pair.normalization(0, d), pair.normalization(1, d)
        u1 = np.empty((n, d + 1))
        u = np.multiply(pair.centred[:, :d], 1.0 / ns.scale, out=u1[:, :d])
        u1[:, d] = 1.0
        X = pair.centred[:, d:]
    Xn = X / nt.scale
    reweight = errors_in == "target" and obs.covariance is None
    # the start: the linearised solution (with errors in the target its equations reweighted
    # by 1 / w_i: first-order coordinate residuals, a start that saves the adjustment an
    # iteration), with the target scale undone below (rows of H_n times kt)
    h_lin, vtv_lin, h0 = _linearised_start(u1, Xn, ns, what, reweight=reweight)
    ks, kt = ns.scale, nt.scale
    names = (Projective2D if d == 2 else Projective3D).names
    linear_info = None
    if statistics:
        # the linearised solution in raw coordinates (what the lecture prints)
        _, p_lin_raw, _ = _proj_back(h_lin[:-1] / h_lin[-1], ns, nt, d, jacobian=False)
        linear_info = {
            "parameters": dict(zip(names, (float(v) for v in p_lin_raw))),
            # raw algebraic residuals are kt times the normalised ones (the constraint fixes
            # the raw last element at 1)
            "vtv": float(vtv_lin * kt**2),
            "redundancy": int(n * d - len(names)),
            "note": "linearised least squares x = a1 x' + a2 y' + a3 - c1 x' x - c2 y' x "
                    "(observations on both sides; residuals are algebraic, not coordinate "
                    "residuals)",
        }
    p0 = h0[:-1] / h0[-1]
    p0[:d * (d + 1)] *= kt
    nt = PointNormalization(nt.centre, 1.0)
    kt = 1.0
    lean = None
    if (errors_in == "target" and not statistics and obs.weights is None
            and obs.covariance is None and n <= LEAN_MAX_POINTS):
        # the same iteration without the general engine's overhead (None: the engine decides)
        lean = gauss_newton_unit(u, X, p0, max_iter, tol, u1=u1)
    if lean is not None:
        p_n, iterations = lean
        adj = BareSolution(p_n, n * d - len(names), n * d, iterations, True,
                           f"converged after {iterations} iteration(s)")
        method = "Gauss-Markov (rational form)"
        note = _NOTE_RATIONAL
        extra_res = None
    elif errors_in == "target":
        w, C = _unit_weights_scaled(n, None, obs)
        rational = RationalModel(u)
        adj = gauss_markov(
            rational.model,
            p0,
            X.reshape(-1),
            jacobian=rational.jacobian,
            weights=w,
            covariance=C,
            sigma0_prior=sigma0_prior,
            names=names,
            max_iter=max_iter,
            tol=tol,
            statistics=statistics,
            what=what,
        )
        method = "Gauss-Markov (rational form)"
        note = _NOTE_RATIONAL
        p_n = adj.x
        extra_res = None
    else:
        factors = np.concatenate([np.full(d, ks), np.full(d, kt)])
        w, C = _unit_weights_scaled(n, factors, obs)
        L = np.column_stack([u, X]).reshape(-1)

        def conditions(p, lk):
            lk = lk.reshape(n, 2 * d)
            Xh, wd = rational_map(homogeneous_matrix(p, d), homogeneous_points(lk[:, :d]))
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
            H = homogeneous_matrix(p, d)
            wd = affine_rows(H[d:], uu)[:, 0]
            blocks = np.zeros((n, d, 2 * d))
            blocks[:, :, :d] = XX[:, :, None] * H[d, :d][None, None, :] - H[None, :d, :d]
            blocks[:, np.arange(d), d + np.arange(d)] = wd[:, None]
            if n * d < SPARSE_FROM:
                return scipy.linalg.block_diag(*blocks) if n > 0 else np.zeros((0, 0))
            from scipy.sparse import block_diag

            return block_diag(list(blocks), format="csr")

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
        if not statistics:  # the same estimate; its statistics are not reported
            tf, p, _ = _proj_back(adj.x, ns, nt, d, jacobian=False)
            return tf, adj, p, None, "Gauss-Helmert (errors in source and target)", "", None, None
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
    tf, p, J = _proj_back(p_n, ns, nt, d, jacobian=statistics)
    return tf, adj, p, J, method, note, linear_info, extra_res


# --- the 3D similarity and rigid models ----------------------------------------------------------


@functools.cache
def _absolute_orientation():
    """:func:`~photogeom.orientation.absolute_orientation`, imported on first use (the
    command ``transform estimate`` of the 2D models does not load the orientation package);
    an import statement in the function body costs several microseconds on every call, some
    5 % of a 10-point fit."""
    from ..orientation.absolute import absolute_orientation

    return absolute_orientation


@functools.cache
def _transpose_angles():
    """:func:`~photogeom.orientation.absolute_stats.transpose_angles`, imported on first use
    (as :func:`_absolute_orientation`)."""
    from ..orientation.absolute_stats import transpose_angles

    return transpose_angles


def _fit_absolute(model, src, dst, weights, covariance, sigma0_prior, statistics, ids, unit,
                  what, need):
    """The 3D similarity / rigid model by :func:`~photogeom.orientation.absolute_orientation`,
    which checks the geometry of both point sets; on degenerate geometry the message names the
    side and the minimum in the words of this module.

    Point weights (or none) use the SVD (the least-squares solution in closed form); weights
    per coordinate (n, 3) or a covariance (n, 3, 3) / (3n, 3n) use the Gauss-Markov
    adjustment started from it, the least-squares solution for that stochastic model (the SVD
    takes one weight per point only)."""
    absolute_orientation = _absolute_orientation()
    method = "svd"
    if covariance is not None or (weights is not None and np.ndim(weights) > 1):
        method = "gauss-markov"
    kwargs: dict = {}
    if weights is not None:
        kwargs["weights"] = weights
    if covariance is not None:
        kwargs["covariance"] = covariance
    if sigma0_prior != 1.0:
        kwargs["sigma0_prior"] = sigma0_prior
    try:
        return absolute_orientation(
            src, dst, method, with_scale=model == "similarity3d", statistics=statistics,
            ids=ids, unit=unit, **kwargs,
        )
    except DegenerateGeometryError:
        _validate_geometry(model, src, dst, need)
        raise


def _helmert_extras(fit: Fit, unit: str = "") -> dict:
    """Geodetic Helmert parameters (EPSG conventions) of a fitted 3D similarity, name ->
    (value, std): shifts in target units (labelled ``unit``, the label of the fit's shifts),
    rotations in arc-seconds, scale difference in ppm.

    Position-vector rotations are the ``"transposed"`` angles omega, phi, kappa, so their
    standard deviations are those of the fit. The coordinate-frame rotations are the angles of
    ``R.T``: their standard deviations are propagated through that exact conversion (its
    Jacobian, :func:`~photogeom.orientation.absolute_stats.transpose_angles`), not copied
    (equal only to first order in the rotation).
    """
    transpose_angles = _transpose_angles()
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
    names = list(fit.parameter_names)
    sd_cf = dict(sd)
    if all(k in names for k in ("omega", "phi", "kappa")):
        idx = [names.index(k) for k in ("omega", "phi", "kappa")]
        _, J = transpose_angles(*(float(fit.parameters[i]) for i in idx))
        C = J @ np.asarray(fit.covariance)[np.ix_(idx, idx)] @ J.T
        s_cf = np.sqrt(np.clip(np.diag(C), 0.0, None)) * sec
        sd_cf.update(rx=float(s_cf[0]), ry=float(s_cf[1]), rz=float(s_cf[2]))
    out: dict = {}
    for conv, sds in (("position_vector", sd), ("coordinate_frame", sd_cf)):
        hp = m.helmert_parameters(conv)
        out[conv] = {k: (float(hp[k]), float(sds[k])) for k in hp}
    out["units"] = {"tx": unit, "ty": unit, "tz": unit, "rx": "arcsec", "ry": "arcsec",
                    "rz": "arcsec", "ds": "ppm"}
    return out


# --- public entry point --------------------------------------------------------------------------


_SINGULAR_AFFINE3D_NOTE = (
    "the fitted linear part is singular (the target points are coplanar or collinear): the "
    "affinity maps space onto a plane (or a line), so it has no inverse and its textbook "
    "decomposition (scales, shears, angles) is undefined (NaN); the parameters a11..a33, "
    "tx..tz are the estimate"
)


_SINGULAR_AFFINE2D_NOTE = (
    "the fitted linear part is singular (the target points are collinear): the affinity maps "
    "the plane onto a line, so it has no inverse (textbook sx = 0); the parameters "
    "a1..a3, b1..b3 are the estimate"
)


def _textbook(model, cofactor: np.ndarray, sigma0: float):
    """Textbook parameters with standard deviations: name -> (value, std); NaN (value, std
    and cofactor) for a singular 3D affinity, whose decomposition is undefined."""
    if isinstance(model, Affine3D) and model.singular:
        # scales, shears, angles undefined; the shifts are the parametric tx, ty, tz
        names = list(model.textbook_units)
        Q = np.full((len(names), len(names)), np.nan)
        Q[-3:, -3:] = cofactor[-3:, -3:]
        std = np.sqrt(np.clip(np.diag(Q), 0.0, None)) * sigma0
        values = np.concatenate([np.full(len(names) - 3, np.nan), model.translation])
        return {n: (float(v), float(s)) for n, v, s in zip(names, values, std)}, Q
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
    source_unit: str = "",
    statistics: bool = True,
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
    source_unit : str
        Unit of the source coordinates (default: ``"px"`` for ``source_system="pixel"``,
        else the target unit). Labels the parameters that convert between the two: the
        linear part of a similarity, affine or projective transformation from pixels to mm
        is in ``"mm/px"``, the denominator of a projective one in ``"1/px"``.
    statistics : bool
        ``True`` (default): the full statistics below. ``False``: the same estimate (the same
        least-squares solution; the projective models still get their nonlinear adjustment),
        returned without statistics, as ``absolute_orientation(..., statistics=False)``
        does: ``fit.residuals`` is empty (shape (0, d); apply ``fit.transform`` to get
        them), ``covariance`` and ``cofactor`` are NaN (shared read-only arrays, as
        ``fit.residuals``), ``sigma0`` is NaN, no normalised
        residuals or redundancy numbers, ``extras`` holds no textbook parameters or
        linearised solution (``fit.model.textbook()`` gives the textbook values); check-point
        residuals are still computed. Bad input raises the same errors.
    max_iter, tol : int, float
        Iteration limit and tolerance of the nonlinear adjustments (projective models).

    Returns
    -------
    Fit
        ``fit.model`` the fitted transformation; ``fit.parameters`` in the parametric form with
        covariance; ``fit.extras["textbook"]``: textbook parameters ``name -> (value, std)``
        (angles in radians) by first-order error propagation of the parametric covariance
        (a-posteriori sigma0); projective fits also carry ``extras["linearised"]``. A 3D
        affinity fitted to coplanar target points has a singular linear part: it is returned
        (with and without statistics) with a note, its textbook scales, shears and angles
        NaN (undefined; ``fit.model.textbook()`` raises), its shifts as estimated.

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
    key = model.strip().lower() if isinstance(model, str) else str(model)
    d = MODELS.get(key)
    if d is None:
        raise InputError(f"unknown transformation model {model!r}; use one of {', '.join(MODELS)}")
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
    if errors_in != "target":
        if errors_in != "both":
            raise InputError(f"errors_in must be 'target' or 'both', not {errors_in!r}")
        if not key.startswith("projective"):
            raise InputError(
                f"errors_in='both' is offered for the projective models; {key} is estimated "
                "with errors in the target coordinates"
            )
    absolute = key in ("similarity3d", "rigid3d")
    if check is None and (absolute or key.startswith("projective")):
        # NaN / inf show in the moments of the absolute orientation and in the scatter of the
        # projective geometry check (one pass, no extra check; _validate_geometry checks the
        # values whenever the scatter is not finite)
        src = as_points(source, d, "source", allow_single=False, finite=False)
        dst = as_points(target, d, "target", allow_single=False, finite=False)
    else:
        src = as_points(source, d, "source", allow_single=False, finite=False)
        dst = as_points(target, d, "target", allow_single=False, finite=False)
        check_finite_magnitude(src, "source", key)
        check_finite_magnitude(dst, "target", key)
    check_same_length(src, dst, "source", "target")
    n = src.shape[0]
    point_ids = None if ids is None else _ids(ids, n)
    is_check = _check_mask(check, n)
    ctrl = None if is_check is None else ~is_check
    nobs = 2 * d if errors_in == "both" else d
    obs = _stochastic_model(weights, covariance, n, nobs, ctrl)
    if not (math.isfinite(sigma0_prior) and sigma0_prior > 0):
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
        if statistics or plan.source_system is not None:
            extras["handedness"] = {
                "source_system": plan.source_system,
                "target_system": plan.target_system,
                "source_flip_y": plan.flip_source,
                "target_flip_y": plan.flip_target,
            }
    elif source_system is not None or target_system is not None:
        raise InputError("source_system / target_system apply to 2D models only")

    need = _min_points(key, order)
    sc, dc = (src, dst) if ctrl is None else (src[ctrl], dst[ctrl])
    if sc.shape[0] < need:
        check_count(sc.shape[0], need, what, _hint(key, order) + (
            f"; {int(is_check.sum())} point(s) are check points" if is_check is not None else ""))
    ctrl_ids = _select_ids(point_ids, ctrl, numbered=is_check is not None)
    labels = ("x", "y") if d == 2 else ("x", "y", "z")
    if absolute:
        w_ctrl = None if weights is None else np.asarray(weights, dtype=float)
        if w_ctrl is not None and ctrl is not None:
            w_ctrl = w_ctrl[ctrl]
        fit = _fit_absolute(key, sc, dc, w_ctrl, obs.covariance, sigma0_prior, statistics,
                            ctrl_ids, unit, what, need)
        if key == "rigid3d":
            m = fit.model
            _set(fit, model=Rigid3D(m.rotation, m.translation))
        extras.update(fit.extras or {})
        if key == "similarity3d" and statistics:
            extras["helmert"] = _helmert_extras(fit, unit)
    else:
        pair = _validate_geometry(key, sc, dc, need)
        if key == "similarity2d":
            tf, adj, p, J = _fit_similarity2d(sc, dc, obs, sigma0_prior, what, statistics)
            method = _METHOD_LINEAR
        elif key in ("affine2d", "affine3d"):
            tf, adj, p, J = _fit_affine(sc, dc, obs, sigma0_prior, what, statistics=statistics)
            method = _METHOD_LINEAR
            if key == "affine3d" and tf.singular:
                notes.append(_SINGULAR_AFFINE3D_NOTE)
            elif key == "affine2d" and tf.singular:
                notes.append(_SINGULAR_AFFINE2D_NOTE)
        elif key.startswith("polynomial"):
            tf, adj, p, J = _fit_polynomial(sc, dc, order, obs, sigma0_prior, what,
                                            statistics=statistics)
            method = _METHOD_LINEAR
            centre = np.array2string(tf.centre, precision=6)
            notes.append(
                f"coefficients refer to reduced source coordinates (x - {centre}) / "
                f"{tf.scale:.6g}; extras['textbook'] holds the plain coefficients"
            )
        else:
            tf, adj, p, J, method, note, lin, extra_res = _fit_projective(
                sc, dc, obs, sigma0_prior, what, errors_in, max_iter, tol, statistics, pair)
            if note:
                notes.append(note)
            if lin is not None:
                extras["linearised"] = lin
            if extra_res is not None:
                extras.update(extra_res)
        src_unit = source_unit or ("px" if source_system == "pixel" else "")
        units = _parameter_units(key, tf, unit, src_unit)
        if statistics:
            fit = Fit.from_adjustment(
                adj, tf, method, point_dim=d, parameters=p, parameter_names=tf.parameter_names,
                jacobian=J, ids=ctrl_ids, residual_labels=labels, residual_unit=unit,
                parameter_units=units,
            )
            textbook, Qtb = _textbook(tf, fit.cofactor, fit.sigma0)
            extras["textbook"] = textbook
            extras["textbook_units"] = _textbook_units(tf, unit, src_unit)
            extras["textbook_cofactor"] = Qtb
        else:
            fit = Fit.without_statistics({
                "model": tf, "method": method, "parameter_names": tf.parameter_names,
                "parameters": p, "sigma0_prior": sigma0_prior, "redundancy": adj.redundancy,
                "n_observations": adj.n_observations, "ids": ctrl_ids,
                "residual_labels": labels, "residual_unit": unit, "parameter_units": units,
                "iterations": adj.iterations, "converged": adj.converged,
                "message": adj.message, "notes": tuple(notes), "extras": extras,
                "elapsed": time.perf_counter() - t0,
            }, d)
            if is_check is None:  # complete: no residuals to report or flip back
                return fit
            notes = []  # they are in fit.notes

    # residuals back in the systems as given (undo the flips)
    if plan is not None and plan.flip_source:
        for name in ("source_residuals", "source_normalized_residuals"):
            if extras.get(name) is not None:
                extras[name] = extras[name] * np.array([1.0, -1.0])
    if plan is not None and plan.flip_target and statistics:
        sign = np.array([1.0, -1.0])
        nr = fit.normalized_residuals
        _set(fit, residuals=fit.residuals * sign,
             normalized_residuals=None if nr is None else nr * sign)
    if is_check is not None:
        chk = fit.model.apply(src[is_check]) - dst[is_check]
        if plan is not None and plan.flip_target:
            chk = chk * np.array([1.0, -1.0])
        _set(fit, check_residuals=chk,
             check_ids=_select_ids(point_ids, is_check, numbered=True))
    _set(fit, notes=tuple(fit.notes) + tuple(notes), extras=extras,
         elapsed=time.perf_counter() - t0)
    return fit


def _set(fit: Fit, **values) -> None:
    """Complete a Fit this function has just built (no one else holds it yet): the frozen
    fields are set in place instead of copying all of them with ``dataclasses.replace``, and
    left as the constructor leaves them: arrays as read-only views, ``extras`` a dict of its
    own whose arrays are read-only views (the other fields are so already)."""
    d = fit.__dict__  # as records.build fills it
    for name, value in values.items():
        if name == "extras" and isinstance(value, (dict, Mapping)):  # dict: no ABC check
            value = {k: read_only_view(v) for k, v in value.items()}
        d[name] = read_only_view(value)


_UNITS: dict = {}


#: Textbook parameters that are scale factors (target unit per source unit).
_SCALE_NAMES = frozenset({"scale", "sx", "sy", "sz", "mx", "my", "mz"})


def _textbook_units(tf, unit: str, source_unit: str) -> dict:
    """Units of the textbook parameters: shifts in the target unit, scale factors in target
    per source unit."""
    src = source_unit or unit
    ratio = "1" if src == unit else f"{unit or '1'}/{src}"
    out = {}
    for k, v in tf.textbook_units.items():
        out[k] = unit if v == "" else (ratio if k in _SCALE_NAMES and v == "1" else v)
    return out


def _parameter_units(key: str, tf, unit: str, source_unit: str = "") -> dict:
    """Units of the parametric parameters (a fresh dict; the computed ones are kept per model,
    names and units)."""
    names = tf.parameter_names
    cache = (key, names, unit, source_unit)
    if cache not in _UNITS:
        if len(_UNITS) > 256:
            _UNITS.clear()
        _UNITS[cache] = _units_of(key, names, unit, source_unit)
    return dict(_UNITS[cache])


def _units_of(key: str, names: tuple, unit: str, source_unit: str = "") -> dict:
    """Units of each parameter: target per source for the linear part, target for shifts,
    1 / source for the denominator of a projective model; polynomial coefficients act on
    reduced (unitless) source coordinates, so they are in target units."""
    src = source_unit or unit
    ratio = "1" if src == unit else f"{unit or '1'}/{src}"
    inverse = f"1/{src}" if src else ""
    if key in ("similarity2d", "affine2d", "affine3d"):
        units = dict.fromkeys(names, ratio)
        shifts = {
            "similarity2d": ("c", "d"),
            "affine2d": ("a3", "b3"),
            "affine3d": ("tx", "ty", "tz"),
        }[key]
        units.update(dict.fromkeys(shifts, unit))
        return units
    if key in ("projective2d", "projective3d"):
        d = 2 if key == "projective2d" else 3
        units = {}
        for k, name in enumerate(names):
            row, col = divmod(k, d + 1)
            if row == d:
                units[name] = inverse
            else:
                units[name] = unit if col == d else ratio
        return units
    if key.startswith("polynomial"):
        return dict.fromkeys(names, unit)
    return dict.fromkeys(names, "")
