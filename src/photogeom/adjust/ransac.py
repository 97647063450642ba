"""RANSAC over batched minimal solvers.

The driver draws many minimal samples at once, hands them to a *batched* solver (one
vectorised call for a whole batch of hypotheses), scores every hypothesis on all points
with a truncated quadratic loss (MSAC), and adapts the number of trials to the best inlier
ratio seen. Refinement on the inliers is left to the estimator that calls it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import DegenerateGeometryError, InputError
from ..records import ReadOnlyRecord


@dataclass(frozen=True, eq=False)
class RansacResult(ReadOnlyRecord):
    """Best hypothesis of a RANSAC run.

    Attributes
    ----------
    model : object
        The best hypothesis, as returned (one element of the batch) by the solver.
    inliers : numpy.ndarray of bool, shape (n,)
    trials : int
        Number of hypotheses drawn.
    score : float
        MSAC cost of the best hypothesis (lower is better).
    """

    model: object
    inliers: np.ndarray
    trials: int
    score: float


def _take(models, i: int):
    if isinstance(models, tuple):
        return tuple(m[i] for m in models)
    return models[i]


def ransac(
    n: int,
    sample_size: int,
    solve: Callable[[np.ndarray], tuple[object, np.ndarray]],
    errors: Callable[[object], np.ndarray],
    threshold: float,
    *,
    confidence: float = 0.999,
    max_trials: int = 10000,
    batch_size: int = 512,
    rng: np.random.Generator | int | None = None,
) -> RansacResult:
    """Run RANSAC.

    Parameters
    ----------
    n : int
        Number of data points.
    sample_size : int
        Points per minimal sample.
    solve : callable
        ``solve(samples)`` with ``samples`` an int array (B, sample_size) returns
        ``(models, valid)``: a batch of B hypotheses (array or tuple of arrays with a leading
        batch axis) and a bool mask of non-degenerate samples.
    errors : callable
        ``errors(models) -> (B, n)`` error of every point (same unit as ``threshold``).
    threshold : float
        Inlier threshold on the error.
    confidence : float
        Probability of drawing at least one outlier-free sample; sets the adaptive trial count.
    max_trials : int
        Upper bound on hypotheses.
    batch_size : int
        Hypotheses per vectorised call.
    rng : numpy Generator, int or None
        Random source (seed for reproducible runs).

    Returns
    -------
    RansacResult
        The best hypothesis (MSAC score), its inlier mask (errors within ``threshold``) and
        the number of hypotheses drawn.
    """
    if n < sample_size:
        raise InputError(f"RANSAC: {n} point(s), a minimal sample needs {sample_size}")
    if not threshold > 0:
        raise InputError("RANSAC: the inlier threshold must be > 0")
    rng = np.random.default_rng(rng)
    best_score = np.inf
    best_model = None
    best_inliers = None
    needed = max_trials
    trials = 0
    t2 = threshold * threshold
    while trials < min(needed, max_trials):
        b = int(min(batch_size, max_trials - trials))
        # sample without replacement inside each row: argpartition of random keys
        if n <= 4 * sample_size:
            samples = np.argsort(rng.random((b, n)), axis=1)[:, :sample_size]
        else:
            samples = rng.integers(0, n, size=(b, sample_size))
            dup = np.any(np.diff(np.sort(samples, axis=1), axis=1) == 0, axis=1)
            while np.any(dup):
                samples[dup] = rng.integers(0, n, size=(int(dup.sum()), sample_size))
                dup = np.any(np.diff(np.sort(samples, axis=1), axis=1) == 0, axis=1)
        trials += b
        models, valid = solve(samples)
        valid = np.asarray(valid, dtype=bool)
        if not np.any(valid):
            continue
        e = np.asarray(errors(models), dtype=float)
        e2 = np.where(np.isfinite(e), e * e, np.inf)
        cost = np.minimum(e2, t2).sum(axis=1)
        cost[~valid] = np.inf
        i = int(np.argmin(cost))
        if cost[i] < best_score:
            best_score = float(cost[i])
            best_model = _take(models, i)
            best_inliers = e2[i] <= t2
            ratio = best_inliers.mean()
            if ratio >= 1.0:
                needed = trials
            elif ratio > 0:
                denom = np.log1p(-(ratio**sample_size))
                needed = int(np.ceil(np.log(1 - confidence) / denom)) if denom < 0 else max_trials
    if best_model is None:
        raise DegenerateGeometryError(
            "RANSAC: every sample was degenerate (coincident or collinear points); check the data"
        )
    return RansacResult(model=best_model, inliers=best_inliers, trials=trials, score=best_score)
