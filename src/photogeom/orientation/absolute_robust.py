"""Robust absolute orientation: RANSAC over minimal samples, and data snooping.

* :func:`ransac_absolute_orientation` - hypotheses from three-point samples, solved in batches
  by the vectorised SVD solver, scored on all points (MSAC, :func:`photogeom.adjust.ransac`),
  then refined on the inliers with any method until the inlier set is stable.
* :func:`snooping_absolute_orientation` - one adjustment at a time: Baarda's w-test (or Pope's
  tau-test) on the normalised residuals; the point with the largest flagged statistic is
  removed and the adjustment repeated until nothing is flagged.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..adjust import ransac
from ..errors import DegenerateGeometryError, InputError, TooFewPointsError
from .absolute import (
    AbsoluteOrientationFit,
    _as_pair,
    _check_finite_pair,
    absolute_orientation,
    normalize_method,
)
from .absolute_direct import solve_three_points

#: Minimal samples whose source triangle has ``|cross| / max_edge^2`` below this are skipped.
MINIMAL_COLLINEAR = 1e-6


def _minimal_solver(x: np.ndarray, X: np.ndarray, with_scale: bool):
    def solve(samples: np.ndarray):
        xs = x[samples]
        Xs = X[samples]
        sol = solve_three_points(xs, Xs, with_scale=with_scale)
        e1 = xs[:, 1] - xs[:, 0]
        e2 = xs[:, 2] - xs[:, 0]
        area = np.linalg.norm(np.cross(e1, e2), axis=1)
        edge = np.maximum(np.einsum("bi,bi->b", e1, e1), np.einsum("bi,bi->b", e2, e2))
        valid = (
            ~sol.degenerate
            & ~sol.reflection
            & (area > MINIMAL_COLLINEAR * edge)
            & np.isfinite(sol.scale)
            & (sol.scale > 0)
        )
        return (sol.scale, sol.rotation, sol.translation), valid

    def errors(models) -> np.ndarray:
        s, R, t = models
        if np.ndim(s) == 0:
            s, R, t = np.array([s]), R[None], t[None]
        pred = s[:, None, None] * np.matmul(R, x.T) + t[:, :, None]  # (B, 3, n)
        d = pred - X.T[None]
        return np.sqrt(np.einsum("bin,bin->bn", d, d))

    return solve, errors


def _per_pair(values, n: int, name: str) -> np.ndarray | None:
    """``values`` given per point pair (leading axis ``n``) so that pairs can be selected: a
    flat per-coordinate array ``(3n,)`` (observations point by point, as
    :func:`absolute_orientation` takes weights) becomes ``(n, 3)``; scalars and None stay."""
    if values is None or np.ndim(values) == 0:
        return values
    a = np.asarray(values, dtype=float)
    if a.shape == (3 * n,) and n > 0:
        return a.reshape(n, 3)
    if a.shape in ((n,), (n, 3)):
        return a
    raise InputError(
        f"{name}: expected shape ({n},) per point, ({n}, 3) or ({3 * n},) per coordinate; "
        f"got {a.shape}"
    )


#: Keywords of :func:`absolute_orientation` that the refinement on the inliers takes from
#: :func:`ransac_absolute_orientation` (the others are RANSAC's own or refused there).
REFINE_OPTIONS = (
    "sigma_source", "covariance_source", "covariance_target", "covariance", "sigma0_prior",
    "scale_method", "initial", "nearest_rotation", "coplanar_threshold", "max_iter", "tol",
    "raise_on_failure",
)  # fmt: skip


#: The refinement keywords with values per point pair (selected for the inliers).
PER_PAIR = ("sigma_source", "covariance_source", "covariance_target", "covariance")


def _refine_options(options: dict, n: int) -> dict:
    """The refinement keywords, checked against ``n`` pairs; precisions of the source and
    covariances kept in a form whose pairs can be selected (see :func:`_select`)."""
    from .absolute import _cov_array, _sigma_array

    unknown = sorted(set(options) - set(REFINE_OPTIONS))
    if unknown:
        raise InputError(f"unexpected keyword argument(s): {', '.join(unknown)}")
    out = dict(options)
    if options.get("sigma_source") is not None:
        out["sigma_source"] = _sigma_array(options["sigma_source"], n, "sigma_source")
    for name in ("covariance_source", "covariance_target", "covariance"):
        if options.get(name) is not None:
            out[name] = _cov_array(options[name], n, name)
    return out


def _select(value, mask: np.ndarray):
    """``value`` of the pairs in ``mask``: scalars and None unchanged, per-pair arrays
    (leading axis n) by row, full (3n, 3n) covariances by their coordinate rows and columns."""
    if value is None or np.ndim(value) == 0:
        return value
    n = mask.shape[0]
    if value.shape == (3 * n, 3 * n):
        idx = np.repeat(mask, 3)
        return value[np.ix_(idx, idx)]
    return value[mask]


def ransac_absolute_orientation(
    source,
    target,
    threshold: float,
    *,
    method: str = "svd",
    with_scale: bool = True,
    confidence: float = 0.999,
    max_trials: int = 10000,
    batch_size: int | None = None,
    rng=None,
    statistics: bool = True,
    max_refinements: int = 10,
    weights=None,
    sigma_target=None,
    ids=None,
    unit: str = "m",
    **refine_options,
) -> AbsoluteOrientationFit:
    """RANSAC absolute orientation with refinement on the inliers.

    Parameters
    ----------
    source, target : array_like, shape (n, 3)
        Putative correspondences (some may be wrong).
    threshold : float
        Inlier distance ``|s R x + t - X|`` in target units (a few times the noise).
    method : str
        Method of the refinement on the inliers (any of
        :func:`~photogeom.orientation.absolute_orientation`'s).
    with_scale : bool
    confidence, max_trials, batch_size, rng
        See :func:`photogeom.adjust.ransac`; ``batch_size`` defaults to a value that keeps
        the (batch x n) error matrix near 2 million entries.
    statistics : bool
        Statistics of the final refinement.
    max_refinements : int
        Re-selections of the inliers with the refined transformation (stops when stable).
    weights, sigma_target : optional
        Precision for the refinement, subset to the inliers: ``weights`` per point (n,) or
        per coordinate (n, 3) / (3n,) (the latter two need ``method="gauss-markov"``),
        ``sigma_target`` a number, per point (n,) or per coordinate (n, 3), in the units of
        the target coordinates.
    ids : sequence, optional
    unit : str
    **refine_options
        Further keywords of :func:`~photogeom.orientation.absolute_orientation` for the
        refinement: ``sigma_source``, ``covariance_source``, ``covariance_target`` (or
        ``covariance``), ``sigma0_prior``, ``scale_method``, ``initial``,
        ``nearest_rotation``, ``coplanar_threshold``, ``max_iter``, ``tol``,
        ``raise_on_failure``; per-pair values are subset to the inliers. Any other keyword
        raises :class:`InputError`.

    Returns
    -------
    AbsoluteOrientationFit
        Estimated from the inliers (``residuals``/``ids`` of the inliers);
        ``extras["inliers"]`` is the bool mask over all n input points,
        ``extras["all_residuals"]`` the residuals of every point, ``extras["ransac_trials"]``
        the number of hypotheses.
    """
    method = normalize_method(method)
    x, X = _as_pair(source, target)
    n = x.shape[0]
    # NaN / inf named by rows, and coordinates whose sums of squares overflow named as such
    # (the samples' solutions would otherwise all come out degenerate)
    _check_finite_pair(x, X)
    if not (threshold is not None and np.isfinite(threshold) and threshold > 0):
        raise InputError(
            f"RANSAC: the inlier threshold must be a positive distance, got {threshold}"
        )
    if ids is not None and len(ids) != n:
        raise InputError(f"ids: {len(ids)} id(s) for {n} point pair(s)")
    w_all = _per_pair(weights, n, "weights")
    st_all = _per_pair(sigma_target, n, "sigma_target")
    refine = _refine_options(refine_options, n)
    if batch_size is None:
        batch_size = int(np.clip(2_000_000 // max(n, 1), 16, 1024))
    solve, errors = _minimal_solver(x, X, with_scale)
    res = ransac(
        n, 3, solve, errors, threshold, confidence=confidence, max_trials=max_trials,
        batch_size=batch_size, rng=rng,
    )
    inliers = np.asarray(res.inliers, dtype=bool)

    def refit(mask, stats):
        if mask.sum() < 3:
            raise TooFewPointsError(
                "RANSAC absolute orientation", int(mask.sum()), 3,
                "too few inliers: raise the threshold or check the correspondences",
            )
        kw = {}
        if w_all is not None:
            kw["weights"] = w_all[mask]
        if st_all is not None:
            kw["sigma_target"] = st_all if np.ndim(st_all) == 0 else st_all[mask]
        kw.update({k: _select(v, mask) if k in PER_PAIR else v for k, v in refine.items()})
        sub_ids = None if ids is None else tuple(np.asarray(ids, dtype=object)[mask])
        return absolute_orientation(
            x[mask], X[mask], method, with_scale=with_scale, statistics=stats, ids=sub_ids,
            unit=unit, **kw,
        )

    rounds = 0
    while rounds < max_refinements:
        rounds += 1
        fit = refit(inliers, False)
        d = np.linalg.norm(fit.transform.apply(x) - X, axis=1)
        new = d <= threshold
        if np.array_equal(new, inliers):
            break
        inliers = new
    fit = refit(inliers, statistics)
    all_res = fit.transform.apply(x) - X
    if ids is None:
        fit = replace(fit, ids=tuple(int(i) for i in np.flatnonzero(inliers)))
    extras = dict(fit.extras)
    extras.update(
        inliers=inliers,
        all_residuals=all_res,
        ransac_trials=res.trials,
        ransac_threshold=float(threshold),
        refinement_rounds=rounds,
    )
    note = (
        f"RANSAC: {int(inliers.sum())} of {n} pairs are inliers (threshold {threshold:g} {unit}, "
        f"{res.trials} hypotheses); estimate refined on the inliers by {method}"
    )
    return replace(fit, extras=extras, notes=(*fit.notes, note))


def snooping_absolute_orientation(
    source,
    target,
    method: str = "gauss-markov",
    *,
    alpha: float = 0.001,
    sigma: str = "posterior",
    max_remove: int | None = None,
    min_points: int = 4,
    ids=None,
    **fit_options,
) -> AbsoluteOrientationFit:
    """Iterated data snooping: remove the worst flagged point and re-adjust, until none is flagged.

    Each round fits ``method`` (any of :func:`absolute_orientation`'s with statistics), tests
    every residual component (``sigma="posterior"``: Pope's tau-test with the a-posteriori
    sigma0, for unknown precision; ``"prior"``: Baarda's w-test, needs realistic
    ``sigma_target``), and removes the point whose largest ``|statistic|`` is the largest of
    all, if it is flagged. Only one point is removed per round (a gross error spreads into the
    residuals of the other points).

    Parameters
    ----------
    source, target : array_like, shape (n, 3)
        Corresponding points, as in :func:`absolute_orientation`.
    method : str
        Estimator of every round (default ``"gauss-markov"``).
    alpha : float
        Significance level of each test (0.001: Baarda's 3.29 for the w-test).
    sigma : {"posterior", "prior"}
        ``"posterior"``: Pope's tau-test with the a-posteriori sigma0; ``"prior"``:
        Baarda's w-test with ``sigma0_prior`` (needs realistic precisions in
        ``fit_options``).
    max_remove : int, optional
        Upper bound on removed points (default: no bound besides ``min_points``).
    min_points : int
        Never go below this number of points (>= 4 keeps redundancy for the test).
    ids : sequence, optional
    fit_options
        Passed to :func:`absolute_orientation` (per-point arrays are subset).

    Returns
    -------
    AbsoluteOrientationFit
        The final adjustment; ``extras["removed"]`` lists the removed input indices in order,
        ``extras["kept"]`` is the mask of kept points, ``extras["snooping"]`` the final test,
        ``extras["alpha"]`` its level (the residual tables of the reports and
        ``to_dict()["snooping"]`` test at it too), ``extras["stopped_by"]``
        ``"max_remove=..."`` or ``"min_points=..."`` when a limit ended the removal while
        points still failed the test (they are then named in ``notes``), else None.
    """
    x, X = _as_pair(source, target)
    n = x.shape[0]
    if min_points < 4:
        raise InputError("min_points must be >= 4 (three points leave too little redundancy)")
    keep = np.ones(n, dtype=bool)
    removed: list[int] = []
    all_ids = None if ids is None else np.asarray(ids, dtype=object)
    if all_ids is not None and all_ids.shape[0] != n:
        raise InputError(f"ids: {all_ids.shape[0]} id(s) for {n} point pair(s)")

    def sub(v):
        if v is None or np.ndim(v) == 0:
            return v
        a = np.asarray(v)
        if a.shape[:1] == (n,):
            return a[keep]
        if a.shape == (3 * n,):  # per coordinate, observations point by point
            return a.reshape(n, 3)[keep].reshape(-1)
        if a.shape[:2] == (3 * n, 3 * n):
            idx = np.repeat(keep, 3)
            return a[np.ix_(idx, idx)]
        return a

    stopped_by = None
    while True:
        opts = {k: sub(v) for k, v in fit_options.items()}
        fit = absolute_orientation(
            x[keep], X[keep], method,
            ids=None if all_ids is None else tuple(all_ids[keep]), **opts,
        )
        if fit.redundancy < 2:
            raise DegenerateGeometryError("data snooping needs a redundancy of at least 2")
        sn = fit.snooping(alpha=alpha, sigma=sigma)
        stat = np.abs(sn.statistic).reshape(-1, 3)
        flagged = sn.flagged.reshape(-1, 3).any(axis=1)
        worst = np.where(np.isfinite(stat), stat, -1.0).max(axis=1)
        j = int(np.argmax(worst))
        if not flagged[j]:
            break
        stopped_by = (
            f"min_points={min_points}" if keep.sum() <= min_points
            else f"max_remove={max_remove}"
            if max_remove is not None and len(removed) >= max_remove else None
        )  # fmt: skip
        if stopped_by is not None:
            break
        orig = int(np.flatnonzero(keep)[j])
        removed.append(orig)
        keep[orig] = False
    extras = dict(fit.extras)
    extras.update(removed=removed, kept=keep.copy(), snooping=sn, stopped_by=stopped_by,
                  alpha=float(alpha))  # fmt: skip
    notes = fit.notes

    def name(i: int):
        return i if all_ids is None else all_ids[i]

    if removed:
        notes = (*notes, f"data snooping ({sn.test}-test, alpha {alpha}) removed: "
                 + ", ".join(str(name(i)) for i in removed))
    if stopped_by is not None:
        left = np.flatnonzero(keep)[flagged]
        order = np.argsort(-worst[flagged])
        shown = ", ".join(
            f"{name(int(i))} (|{sn.test}| {w:.2f})"
            for i, w in zip(left[order][:10], worst[flagged][order][:10])
        )
        notes = (*notes, f"data snooping stopped by {stopped_by} with {int(flagged.sum())} "
                 f"point(s) still failing the {sn.test}-test (critical value "
                 f"{sn.critical_value:.2f}): {shown}; they are in the final adjustment")
    return replace(fit, extras=extras, notes=notes)
