"""Variance-component estimation (Förstner / Helmert iteration) for groups of observations.

An adjustment whose observations fall into groups ``k`` with weights ``P_k = Q_k^-1 /
s_k^2`` estimates the variance factors ``s_k^2`` iteratively: after each solve, the
group's weighted sum of squared residuals ``v_k' P_k v_k`` and its redundancy contribution
``r_k = tr(Qvv P)_k`` (summing to the total redundancy) give the factor

    f_k = v_k' P_k v_k / r_k

by which the group's variance is multiplied (its weight divided) before the next solve. At
convergence every ``f_k`` is 1, i.e. each group's own a-posteriori variance of unit weight
is 1 (Förstner 1979; the same fixed point as Helmert's estimator for block-diagonal P).

The functions here see only these per-group numbers, never the adjustment, so that every
estimator (the finite-element residual grids, the bundle adjustment) can use them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import InputError


def variance_factors(vtpv: Sequence[float], redundancy: Sequence[float]) -> np.ndarray:
    """One Förstner update: the factors ``f_k = v_k' P_k v_k / r_k`` of every group.

    Parameters
    ----------
    vtpv : sequence of float, shape (g,)
        Weighted sum of squared residuals of each group (current weights).
    redundancy : sequence of float, shape (g,)
        Redundancy contribution of each group, ``r_k = sum of the diagonal of Qvv P`` over
        the group's observations.

    Returns
    -------
    numpy.ndarray, shape (g,)
        Multiply each group's variance by its factor (divide its weights by it).

    Raises
    ------
    InputError
        A group without redundancy (``r_k <= 0``: its variance cannot be estimated; merge it
        with another group or give its weight), or non-finite / negative inputs.
    """
    v = np.asarray(vtpv, dtype=float)
    r = np.asarray(redundancy, dtype=float)
    if v.shape != r.shape or v.ndim != 1:
        raise InputError("vtpv and redundancy must be 1-D arrays of the same length (groups)")
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(r))):
        raise InputError("variance components: vtpv and redundancy must be finite")
    if np.any(v < 0):
        raise InputError("variance components: vtpv must be non-negative")
    bad = np.flatnonzero(~(r > 1e-12))
    if bad.size:
        raise InputError(
            f"variance components: group(s) {', '.join(map(str, bad))} have no redundancy "
            "(r_k <= 0), so their variance cannot be estimated; give their weight instead"
        )
    return v / r


def converged(factors: Sequence[float], tol: float = 1e-3) -> bool:
    """True when every factor is within ``tol`` of 1 (relative change of the variances)."""
    f = np.asarray(factors, dtype=float)
    return bool(np.all(np.abs(f - 1.0) <= tol))
