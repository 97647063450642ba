"""Orientation estimators: absolute orientation, space resection and intersection."""

from .absolute import (
    DIRECT_METHODS,
    METHODS,
    AbsoluteOrientationFit,
    absolute_orientation,
)
from .absolute_batch import BatchOrientation, absolute_orientation_batch
from .absolute_compare import MethodComparison, compare_absolute_methods
from .absolute_robust import ransac_absolute_orientation, snooping_absolute_orientation

__all__ = [
    "DIRECT_METHODS",
    "METHODS",
    "AbsoluteOrientationFit",
    "BatchOrientation",
    "MethodComparison",
    "absolute_orientation",
    "absolute_orientation_batch",
    "compare_absolute_methods",
    "ransac_absolute_orientation",
    "snooping_absolute_orientation",
]
