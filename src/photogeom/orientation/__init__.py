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
from .relative import ImagePair, RelativeOrientationFit, relative_orientation
from .stereo_model import ModelPoints, ParallaxReport, model_points, parallax_report
from .strip import BlockStart, StripModel, block_start, orient_strip, points_from_exteriors

__all__ = [
    "DIRECT_METHODS",
    "METHODS",
    "AbsoluteOrientationFit",
    "BatchOrientation",
    "BlockStart",
    "ImagePair",
    "MethodComparison",
    "ModelPoints",
    "ParallaxReport",
    "RelativeOrientationFit",
    "StripModel",
    "absolute_orientation",
    "absolute_orientation_batch",
    "block_start",
    "compare_absolute_methods",
    "model_points",
    "orient_strip",
    "parallax_report",
    "points_from_exteriors",
    "ransac_absolute_orientation",
    "relative_orientation",
    "snooping_absolute_orientation",
]
