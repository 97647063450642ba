"""Blocks of images and their bundle adjustment with self-calibration.

* :class:`Block` - camera groups, images, points and observations keyed by ids;
* :func:`reprojection_residuals` - computed minus observed pixels of every observation;
"""

from .block import CALIBRATION_NAMES, DEFAULT_FREE, Block, Image, Observations, Point
from .residuals import projected_pixels, reprojection_residuals

__all__ = [
    "CALIBRATION_NAMES",
    "DEFAULT_FREE",
    "Block",
    "Image",
    "Observations",
    "Point",
    "projected_pixels",
    "reprojection_residuals",
]
