"""Variance-component estimation: the update of the variance factors of observation groups.

For groups k of observations with a-priori weights ``P_k / f_k`` (``f_k`` the current
variance factor), whitened squared residual sums ``v_k'P_k v_k`` and redundancy
contributions ``r_k = n_k - tr(P_k A Q A')`` (Förstner 1979; Helmert's estimator in its
iterated form), the estimate of the factor is ``f_k * v_k'P_k v_k / r_k``. Iterating the
adjustment with the new factors until every ratio is 1 gives the variance components.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError


def update_variance_factors(
    factors, weighted_squares, redundancies, *, min_redundancy: float = 1e-6
) -> tuple[np.ndarray, np.ndarray]:
    """New variance factors and the ratios ``v'Pv / r`` of each group.

    Parameters
    ----------
    factors : array_like (k,)
        Current variance factors (the a-priori variances are multiplied by them).
    weighted_squares : array_like (k,)
        ``v_k' P_k v_k`` of each group with the current weights.
    redundancies : array_like (k,)
        Redundancy contribution ``r_k`` of each group (sums of redundancy numbers).

    Raises
    ------
    InputError
        A group without redundancy (its variance cannot be estimated: it is not controlled
        by the other observations).
    """
    f = np.asarray(factors, dtype=float)
    q = np.asarray(weighted_squares, dtype=float)
    r = np.asarray(redundancies, dtype=float)
    if np.any(r <= min_redundancy):
        raise InputError(
            "variance-component estimation: a group has no redundancy (its observations are "
            "not controlled by the others); its variance cannot be estimated"
        )
    ratio = q / r
    return f * ratio, ratio
