"""Baarda's data snooping (w-test) and Pope's tau-test on normalised residuals."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..errors import InputError
from ..records import ReadOnlyRecord
from .result import Adjustment

#: Power of the w-test at which the minimal detectable bias is given (Baarda's 80 %).
POWER = 0.8
#: Redundancy number below which an observation is reported as poorly controlled: a gross
#: error there shows in its own residual with less than a tenth of its size (in units of the
#: residual's standard deviation, ``sqrt(r_i)`` of it), so its minimal detectable bias exceeds
#: ``3.2 delta0`` (13 standard deviations of the observation at alpha 0.001, power 0.8).
POORLY_CONTROLLED = 0.1


@dataclass(frozen=True, eq=False)
class SnoopingResult(ReadOnlyRecord):
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
    redundancy_numbers : numpy.ndarray or None, shape (n_obs,)
        ``r_i = (Qvv P)_ii`` (dimensionless, summing to the redundancy), when the adjustment
        carries them.
    mdb : numpy.ndarray or None, shape (n_obs,)
        Minimal detectable bias of every observation, in units of its own a-priori
        standard deviation: ``delta0 / sqrt(r_i)``, the gross error that the w-test at
        ``alpha`` finds with probability :data:`POWER` (internal reliability; exact for
        uncorrelated observations of a least-squares adjustment). Infinite where ``r_i`` is
        ~0 (the error is absorbed by the parameters: undetectable).
    """

    statistic: np.ndarray
    test: str
    alpha: float
    critical_value: float
    flagged: np.ndarray
    redundancy_numbers: np.ndarray | None = None
    mdb: np.ndarray | None = None

    @property
    def poorly_controlled(self) -> np.ndarray:
        """Mask of observations with ``r_i`` below :data:`POORLY_CONTROLLED` (all False
        without redundancy numbers): a gross error there can pass the test unnoticed."""
        if self.redundancy_numbers is None:
            return np.zeros(np.shape(self.statistic), dtype=bool)
        with np.errstate(invalid="ignore"):
            return ~(np.asarray(self.redundancy_numbers, dtype=float) >= POORLY_CONTROLLED)

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
        """JSON-ready summary.

        Returns
        -------
        dict
            ``test``, ``alpha``, ``critical_value``, ``statistic`` per observation (None
            where it cannot be formed), ``flagged`` indices, ``power``, ``mdb`` (minimal
            detectable errors, in standard deviations) and ``poorly_controlled`` indices.
        """
        return {
            "test": self.test,
            "alpha": self.alpha,
            "critical_value": self.critical_value,
            "statistic": [None if not np.isfinite(x) else float(x) for x in self.statistic],
            "flagged": [int(i) for i in np.flatnonzero(self.flagged)],
            "power": POWER,
            "mdb": None if self.mdb is None else [
                None if not np.isfinite(x) else float(x) for x in self.mdb
            ],
            "poorly_controlled": [int(i) for i in np.flatnonzero(self.poorly_controlled)],
        }


def w_critical_value(alpha: float) -> float:
    """Critical value of Baarda's w-test (standard normal, two-sided) at level ``alpha``."""
    from scipy.special import ndtri  # normal quantile (scipy.stats is slow to import)

    if not 0 < alpha < 1:
        raise InputError(f"alpha must be in (0, 1), got {alpha}")
    return float(ndtri(1 - alpha / 2))


def noncentrality(alpha: float, power: float = POWER) -> float:
    """Baarda's ``delta0``: the shift of a unit normal statistic that the two-sided test at
    level ``alpha`` detects with probability ``power`` (``lambda0 = delta0^2``).

    Solves ``Phi(delta0 - c) + Phi(-delta0 - c) = power`` with ``c`` the critical value
    (alpha 0.001, power 0.8: 4.13, the textbook ``3.29 + 0.84``).
    """
    # bisection on the increasing power function (scipy.optimize, which a root finder would
    # need, takes longer to import than a small estimate takes to run)
    from scipy.special import ndtri

    if not 0 < power < 1:
        raise InputError(f"power must be in (0, 1), got {power}")
    c = w_critical_value(alpha)
    if power <= alpha:
        return 0.0

    def detected(d: float) -> float:  # Phi(d - c) + Phi(-d - c), by erfc (no cancellation)
        return 0.5 * (math.erfc((c - d) / math.sqrt(2.0)) + math.erfc((d + c) / math.sqrt(2.0)))

    lo, hi = 0.0, c + float(ndtri(power)) + 1.0
    while hi - lo > 1e-13 * max(1.0, hi):
        mid = 0.5 * (lo + hi)
        if detected(mid) < power:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


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
        The test statistic of every observation (dimensionless), the critical value, the
        flagged observations and, when the adjustment has redundancy numbers, the minimal
        detectable bias of every observation (units of its standard deviation) and the
        poorly controlled ones (``r_i`` below :data:`POORLY_CONTROLLED`).

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
    red = adjustment.redundancy_numbers
    mdb = None
    if red is not None:
        red = np.asarray(red, dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            mdb = np.where(red > 1e-14, noncentrality(alpha) / np.sqrt(np.abs(red)), np.inf)
        mdb[np.isnan(red)] = np.nan
    return SnoopingResult(
        statistic=stat,
        test=test,
        alpha=alpha,
        critical_value=crit,
        flagged=flagged,
        redundancy_numbers=red,
        mdb=mdb,
    )
