"""Blocks of images and their bundle adjustment with self-calibration.

* :class:`Block` - camera groups, images, points and observations keyed by ids;
* :func:`reprojection_residuals` - computed minus observed pixels of every observation;
* :func:`triangulate` - points from their observations with the cameras fixed (vectorised);
"""

from .block import CALIBRATION_NAMES, DEFAULT_FREE, Block, Image, Observations, Point
from .residuals import projected_pixels, reprojection_residuals
from .triangulate import Triangulation, triangulate

__all__ = [
    "CALIBRATION_NAMES",
    "DEFAULT_FREE",
    "Block",
    "Image",
    "Observations",
    "Point",
    "Triangulation",
    "projected_pixels",
    "reprojection_residuals",
    "triangulate",
]
