"""The least-squares engine used by every estimator.

* :func:`solve_linear` - linear Gauss-Markov model ``L + v = A x``;
* :func:`gauss_markov` - nonlinear Gauss-Markov model ``L + v = f(x)`` (Gauss-Newton);
* :func:`gauss_helmert` - Gauss-Helmert model ``g(x, L + v) = 0`` (errors in all observations);
* :func:`data_snooping` - Baarda's w-test (and Pope's tau-test) on normalised residuals;
* :func:`ransac` - a RANSAC driver over batched minimal solvers;
* :func:`~photogeom.adjust.levenberg.levenberg_marquardt_loop` - the damped loop of the
  sparse adjustments (the bundle adjustment, grids inside it);
* :class:`Adjustment` - the low-level result; :class:`Fit` - the result family of estimators.

Residuals are **computed minus observed** (``v = A x - L``) throughout.
"""

from .conditioning import PointNormalization, normalize_points
from .fit import Fit, propagate_covariance
from .gauss_helmert import gauss_helmert
from .gauss_markov import gauss_markov, solve_linear
from .ransac import RansacResult, ransac
from .result import Adjustment
from .snooping import SnoopingResult, data_snooping

__all__ = [
    "Adjustment",
    "Fit",
    "PointNormalization",
    "RansacResult",
    "SnoopingResult",
    "data_snooping",
    "gauss_helmert",
    "gauss_markov",
    "normalize_points",
    "propagate_covariance",
    "ransac",
    "solve_linear",
]
