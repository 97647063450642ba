"""Absolute orientation of point sets too large for memory: moments chunk by chunk.

The direct solvers (SVD, quaternion, dual quaternion, direct Gauss-Helmert) need only the
weighted moments of the two point sets (centroids, cross-covariance ``H``, sums of squares).
Here each chunk of corresponding points gives its *centred* moments (by the in-memory
accumulator :func:`~photogeom.orientation.absolute_direct.large_moments`), and chunks are
merged with the pairwise update of Chan, Golub & LeVeque (1979):

    W = W1 + W2,   d = m2 - m1 (centroid differences),
    H = H1 + H2 + (W1 W2 / W) dx dX.T,   a = a1 + a2 + (W1 W2 / W) |dx|^2

which is exact in exact arithmetic and loses no digits for coordinates far from the origin.
Every chunk is read once (one pass over the data); chunks can be computed anywhere (a
``dask.array`` block per task: :func:`photogeom.distributed.absolute_orientation`) and merged
in any order. The solution is the in-memory one (``absolute_orientation(...,
statistics=False)``) to rounding.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable

import numpy as np

from ..adjust.result import not_computed
from ..errors import InputError
from . import absolute_adjust as _adj
from .absolute import (
    _CONVENTION_NOTE,
    _GIMBAL_NOTE,
    AbsoluteOrientationFit,
    _check_solution,
    _Context,
    _params,
    _similarity,
    _stat_fit,
)
from .absolute_direct import PairMoments, large_moments, solve_single
from .absolute_stats import LinearisedStatistics, _cofactor, opk_transposed

#: Methods that work from moments alone.
MOMENT_METHODS = ("svd", "quaternion", "dual-quaternion", "gauss-helmert")


def chunk_moments(x, X, w=None) -> tuple:
    """Centred moments of one chunk of pairs ``x``, ``X`` (m, 3), weights ``w`` (m,).

    Returns the tuple ``(W, xg, Xg, H, a, b, bad, S)`` of plain numbers and
    small arrays (cheap to send between processes): weight sum, centroids, centred
    cross-covariance, centred sums of squares, the count of non-finite values found (0 for
    clean data) and the centred source scatter ``sum w x' x'.T`` (for the covariance of the
    parameters).
    """
    x = np.ascontiguousarray(x, dtype=float)
    X = np.ascontiguousarray(X, dtype=float)
    if x.shape != X.shape or x.ndim != 2 or x.shape[1] != 3:
        raise InputError(
            f"chunks of source and target must both have shape (m, 3); got {x.shape}, {X.shape}"
        )
    if w is not None:
        w = np.ascontiguousarray(w, dtype=float)
    m = x.shape[0]
    if m == 0:
        z = np.zeros(3)
        return 0.0, z, z, np.zeros((3, 3)), 0.0, 0.0, 0, np.zeros((3, 3))
    # the in-memory accumulator: one pass, about a reference near the data, with its own
    # second pass (over this chunk only) should the first show cancellation
    mo = large_moments(x, X, w, scatter=True)
    H, a, b, S = mo.H[0], float(mo.a[0]), float(mo.b[0]), mo.S[0]
    xg, Xg = mo.source_centroid[0], mo.target_centroid[0]
    bad = 0
    if not (math.isfinite(a + b) and np.all(np.isfinite(H)) and np.all(np.isfinite(xg + Xg))):
        bad = int(np.count_nonzero(~np.isfinite(x)) + np.count_nonzero(~np.isfinite(X)))
        bad = max(bad, 1)
    return float(mo.weight[0]), xg, Xg, H, a, b, bad, S


def merge_moments(parts: Iterable[tuple]) -> tuple:
    """Merge chunk moments (:func:`chunk_moments` tuples) into the moments of the union."""
    W = 0.0
    xg = np.zeros(3)
    Xg = np.zeros(3)
    H = np.zeros((3, 3))
    S = np.zeros((3, 3))
    a = b = 0.0
    bad = 0
    for W2, x2, X2, H2, a2, b2, bad2, S2 in parts:
        bad += int(bad2)
        if W2 == 0:
            continue
        if W == 0:
            W, xg, Xg, H, a, b = W2, np.array(x2), np.array(X2), np.array(H2), a2, b2
            S = np.array(S2)
            continue
        Wt = W + W2
        dx = np.asarray(x2) - xg
        dX = np.asarray(X2) - Xg
        f = W * W2 / Wt
        H = H + H2 + f * np.outer(dx, dX)
        S = S + np.asarray(S2) + f * np.outer(dx, dx)
        a = a + a2 + f * float(dx @ dx)
        b = b + b2 + f * float(dX @ dX)
        xg = xg + dx * (W2 / Wt)
        Xg = Xg + dX * (W2 / Wt)
        W = Wt
    return W, xg, Xg, H, a, b, bad, S


def fit_from_moments(
    moments: tuple,
    n: int,
    *,
    method: str = "svd",
    with_scale: bool = True,
    scale_method: str = "least-squares",
    unit: str = "m",
    t0: float | None = None,
) -> AbsoluteOrientationFit:
    """The absolute orientation from merged moments (:func:`merge_moments`) of ``n`` pairs.

    The parameters are those of ``absolute_orientation(x, X, method=method)`` on the same
    points, to rounding. So are sigma0, the cofactor and the covariance of the parameters:
    they need only the moments (the source scatter, the weight sum and ``v'Pv``). What needs
    the points one by one is not computed: residuals, redundancy numbers and w-tests.

    ``v'Pv = s^2 a - 2 s trace(R H) + b`` (weighted; also ``extras["sum_squared_residuals"]``)
    comes from the moments: accurate when the residuals are not tiny compared with the point
    spread (relative error ~1e-16 spread^2 / residual^2, e.g. 1e-6 for 1 cm residuals over
    1 km).
    """
    t0 = time.perf_counter() if t0 is None else t0
    if method not in MOMENT_METHODS:
        raise InputError(
            f"method {method!r} needs all points at once; out of core: {', '.join(MOMENT_METHODS)}"
        )
    W, xg, Xg, H, a, b, bad, S = moments
    if bad:
        raise InputError(
            f"{bad} NaN or infinite coordinate value(s) in the point sets; remove those points"
        )
    if n < 3:
        raise InputError(f"absolute orientation needs at least 3 point pairs, got {n}")
    pm = PairMoments(
        float(W), np.asarray(xg), np.asarray(Xg), np.asarray(H), float(a), float(b),
        np.asarray(S, dtype=float),
    )
    sol = solve_single(pm, method, with_scale=with_scale, scale_method=scale_method)
    _check_solution(sol.degenerate, sol.reflection, method)
    s, R, t = sol.scale, sol.rotation, sol.translation
    notes = [
        _CONVENTION_NOTE,
        f"out of core: moments merged from chunks ({n} pairs); sigma0 and the covariance of "
        "the parameters from the moments, no per-point residuals or tests",
    ]
    omega, phi, kappa, gimbal = opk_transposed(R)
    if gimbal:
        notes.append(_GIMBAL_NOTE)
    names = _adj.names(with_scale)
    u = len(names)
    params = _params(t, s, (omega, phi, kappa), with_scale)
    r = 3 * n - u
    vtv = s * s * pm.a - 2.0 * s * float(np.trace(R @ pm.H)) + pm.b
    vtv = ssr = max(vtv, 0.0) if math.isfinite(vtv) else math.nan
    Q, _ = _cofactor(pm.S, pm.weight, scale=s, angles=(omega, phi, kappa),
                     source_centroid=pm.source_centroid, with_scale=with_scale)
    n_obs = 3 * n
    if method == "gauss-helmert":
        # errors in both systems, one sigma each: the misclosure s R x + t - X of a pair has
        # the cofactor (1 + s^2) I, which scales v'Pv and the cofactor of the parameters
        m2 = 1.0 + s * s
        vtv, Q, n_obs = vtv / m2, Q * m2, 6 * n
    # the Fit of the in-memory statistics, without what needs the points one by one
    st = LinearisedStatistics(Q, vtv, None, None, None)
    ctx = _Context(n=n, ids=None, unit=unit, t0=t0)
    return _stat_fit(
        _similarity(s, R, t), method, names, params, st, r, n_obs, not_computed((0, 3)),
        with_scale, ctx, notes, extras={"sum_squared_residuals": ssr},
    )


def absolute_orientation_chunks(
    chunks: Iterable,
    *,
    method: str = "svd",
    with_scale: bool = True,
    scale_method: str = "least-squares",
    unit: str = "m",
) -> AbsoluteOrientationFit:
    """Absolute orientation from an iterable of chunks ``(x, X)`` or ``(x, X, w)`` (each
    (m, 3) numpy arrays of corresponding points), read once, e.g. from two files."""
    t0 = time.perf_counter()
    n = 0
    parts = []
    for ch in chunks:
        x, X, *rest = ch
        parts.append(chunk_moments(x, X, rest[0] if rest else None))
        n += int(np.shape(x)[0])
        if len(parts) > 64:  # keep the list short: merge as we go
            parts = [merge_moments(parts)]
    return fit_from_moments(
        merge_moments(parts),
        n,
        method=method,
        with_scale=with_scale,
        scale_method=scale_method,
        unit=unit,
        t0=t0,
    )
