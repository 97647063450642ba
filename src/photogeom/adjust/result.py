"""The low-level result of one least-squares adjustment."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..records import read_only_fields, setstate_read_only


@dataclass(frozen=True)
class Adjustment:
    """Estimate and statistics of one adjustment (Gauss-Markov or Gauss-Helmert).

    Attributes
    ----------
    x : numpy.ndarray, shape (u,)
        Estimated parameters.
    names : tuple of str
        Parameter names, in the order of ``x``.
    residuals : numpy.ndarray, shape (n_obs,)
        ``v`` = computed (adjusted) minus observed, for every observation.
    cofactor : numpy.ndarray, shape (u, u)
        ``Qxx = (A.T P A)^-1`` (Gauss-Helmert: ``(A.T (B Q B.T)^-1 A)^-1``).
    redundancy : int
        ``r = n_conditions - u (+ constraints)``.
    n_observations : int
        Number of observations (Gauss-Helmert: of condition equations).
    vtpv : float
        Weighted sum of squared residuals ``v.T P v``.
    sigma0_prior : float
        A-priori standard deviation of unit weight.
    redundancy_numbers : numpy.ndarray or None, shape (n_obs,)
        Diagonal of ``Qvv P`` (each in [0, 1], summing to ``r``) when available.
    normalized_residuals : numpy.ndarray or None, shape (n_obs,)
        Baarda's ``w_i = (P v)_i / (sigma0_prior sqrt((P Qvv P)_ii))`` when available.
    iterations : int
        Gauss-Newton iterations (0 for a linear solve).
    converged : bool
        ``True`` when the iteration met its criterion (always for a linear solve).
    cost_history : tuple of float
        ``v.T P v`` after each iteration (for diagnostics).
    message : str
        Human-readable account of convergence or problems.
    corrected_observations : numpy.ndarray or None, shape (n_obs,)
        Gauss-Helmert: the adjusted observations ``L + v``; None for Gauss-Markov.

    Notes
    -----
    The arrays are read-only views (take a copy to change one).
    """

    x: np.ndarray
    names: tuple[str, ...]
    residuals: np.ndarray
    cofactor: np.ndarray
    redundancy: int
    n_observations: int
    vtpv: float
    sigma0_prior: float = 1.0
    redundancy_numbers: np.ndarray | None = None
    normalized_residuals: np.ndarray | None = None
    iterations: int = 0
    converged: bool = True
    cost_history: tuple[float, ...] = field(default_factory=tuple)
    message: str = ""
    corrected_observations: np.ndarray | None = None

    #: :func:`photogeom.records.build` may fill the fields and call ``__post_init__``.
    _build_post_init = True

    def __post_init__(self) -> None:
        # read-only views: a Fit built from this adjustment holds its arrays (its covariance
        # was computed from the cofactor: a write into it made the two disagree)
        read_only_fields(self)

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)  # pickle / deepcopy: the arrays stay read-only

    @property
    def sigma0(self) -> float:
        """A-posteriori ``sqrt(v.T P v / r)``; NaN when the redundancy is 0 (undefined)."""
        if self.redundancy <= 0:
            return float("nan")
        return float(np.sqrt(max(self.vtpv, 0.0) / self.redundancy))

    @property
    def covariance(self) -> np.ndarray:
        """A-posteriori covariance ``sigma0^2 Qxx`` (NaN-filled when r = 0)."""
        return self.sigma0**2 * self.cofactor

    @property
    def covariance_prior(self) -> np.ndarray:
        """A-priori covariance ``sigma0_prior^2 Qxx``."""
        return self.sigma0_prior**2 * self.cofactor

    @property
    def std(self) -> np.ndarray:
        """A-posteriori standard deviations of the parameters."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))


class BareSolution(NamedTuple):
    """What a solver run without statistics reports (the fields a ``statistics=False`` Fit
    takes from an :class:`Adjustment`, which has them too): for estimators whose small
    problems skip the general engine."""

    x: np.ndarray
    redundancy: int
    n_observations: int
    iterations: int
    converged: bool
    message: str


#: The note of every Fit returned with ``statistics=False``.
NO_STATISTICS_NOTE = "statistics=False: no residuals or statistics computed"

_NOT_COMPUTED: dict = {}


def not_computed(shape: tuple[int, ...]) -> np.ndarray:
    """A shared read-only array of ``shape`` standing for statistics that were not computed
    (``statistics=False``): NaN-filled, or empty when ``shape`` has a zero. Cached per shape."""
    a = _NOT_COMPUTED.get(shape)
    if a is None:
        if len(_NOT_COMPUTED) > 64:
            _NOT_COMPUTED.clear()
        a = np.full(shape, math.nan)
        a.flags.writeable = False
        _NOT_COMPUTED[shape] = a
    return a
