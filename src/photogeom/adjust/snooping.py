"""Baarda's data snooping (w-test) and Pope's tau-test on normalised residuals."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..errors import InputError
from .result import Adjustment


@dataclass(frozen=True, eq=False)
class SnoopingResult:
    """Outcome of data snooping over all observations.

    Attributes
    ----------
    statistic : numpy.ndarray, shape (n_obs,)
        ``w_i`` (a-priori sigma0, Baarda) or ``tau_i`` (a-posteriori sigma0, Pope);
        NaN for observations without redundancy (``r_i`` ~ 0: not controllable).
    test : {"w", "tau"}
    alpha : float
        Significance level of each single test.
    critical_value : float
    flagged : numpy.ndarray of bool
        ``|statistic| > critical_value``.
    """

    statistic: np.ndarray
    test: str
    alpha: float
    critical_value: float
    flagged: np.ndarray

    @property
    def largest(self) -> int | None:
        """Index of the largest ``|statistic|`` (the prime suspect), None if all NaN."""
        s = np.abs(self.statistic)
        if not np.any(np.isfinite(s)):
            return None
        return int(np.nanargmax(s))

    @property
    def suspect(self) -> int | None:
        """Index of the observation to remove first, or None when nothing is flagged."""
        i = self.largest
        return i if i is not None and bool(self.flagged[i]) else None

    def to_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "test": self.test,
            "alpha": self.alpha,
            "critical_value": self.critical_value,
            "statistic": [None if not np.isfinite(x) else float(x) for x in self.statistic],
            "flagged": [int(i) for i in np.flatnonzero(self.flagged)],
        }


def w_critical_value(alpha: float) -> float:
    """Critical value of Baarda's w-test (standard normal, two-sided) at level ``alpha``."""
    from scipy.special import ndtri  # normal quantile (scipy.stats is slow to import)

    if not 0 < alpha < 1:
        raise InputError(f"alpha must be in (0, 1), got {alpha}")
    return float(ndtri(1 - alpha / 2))


def tau_critical_value(alpha: float, redundancy: int) -> float:
    """Critical value of Pope's tau distribution (two-sided), ``r > 1``."""
    # scipy.special's quantile functions, not scipy.stats (which takes a second to import)
    from scipy.special import stdtrit

    if redundancy <= 1:
        raise InputError("the tau-test needs a redundancy of at least 2")
    t = stdtrit(redundancy - 1, 1 - alpha / 2)  # Student t quantile
    return float(t * np.sqrt(redundancy) / np.sqrt(redundancy - 1 + t * t))


def data_snooping(
    adjustment: Adjustment,
    alpha: float = 0.001,
    sigma: Literal["prior", "posterior"] = "prior",
) -> SnoopingResult:
    """Test every observation for a gross error.

    Parameters
    ----------
    adjustment : Adjustment
        Must carry ``normalized_residuals`` (computed for unit/diagonal weights and for
        full covariances of up to 20000 observations).
    alpha : float
        Significance level of each test (Baarda's usual 0.001: critical value 3.29).
    sigma : {"prior", "posterior"}
        ``"prior"``: Baarda's w-test with sigma0_prior (needs realistic a-priori weights);
        ``"posterior"``: Pope's tau-test with the a-posteriori sigma0.

    Returns
    -------
    SnoopingResult
        The test statistic of every observation (dimensionless), the critical value and the
        flagged observations.

    Raises
    ------
    InputError
        The adjustment has no normalised residuals; ``alpha`` not in (0, 1); ``sigma`` is
        neither ``"prior"`` nor ``"posterior"``; for the tau-test, an a-posteriori sigma0
        that is not finite or is zero, or a redundancy below 2.
    """
    if adjustment.normalized_residuals is None:
        raise InputError(
            "data snooping needs the normalised residuals, which were not computed for this "
            "adjustment (too many correlated observations)"
        )
    if not 0 < alpha < 1:
        raise InputError(f"alpha must be in (0, 1), got {alpha}")
    w = np.asarray(adjustment.normalized_residuals, dtype=float)
    if sigma == "prior":
        stat, test = w, "w"
        crit = w_critical_value(alpha)
    elif sigma == "posterior":
        s0 = adjustment.sigma0
        if not np.isfinite(s0) or s0 == 0:
            raise InputError("the tau-test needs a finite, non-zero a-posteriori sigma0")
        stat, test = w * adjustment.sigma0_prior / s0, "tau"
        crit = tau_critical_value(alpha, adjustment.redundancy)
    else:
        raise InputError(f"sigma must be 'prior' or 'posterior', not {sigma!r}")
    with np.errstate(invalid="ignore"):
        flagged = np.abs(stat) > crit
    return SnoopingResult(
        statistic=stat, test=test, alpha=alpha, critical_value=crit, flagged=flagged
    )
