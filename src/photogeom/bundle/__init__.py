"""Blocks of images and their bundle adjustment with self-calibration.

* :class:`Block` - camera groups, images, points and observations keyed by ids;
* :func:`bundle_adjust` - Levenberg-Marquardt on the reduced camera system, returning a
  :class:`BundleFit` with the adjusted block and its statistics;
* :func:`reprojection_residuals` - computed minus observed pixels of every observation;
* :func:`triangulate` - points from their observations with the cameras fixed (vectorised).
"""

from .adjustment import bundle_adjust
from .block import CALIBRATION_NAMES, DEFAULT_FREE, Block, Image, Observations, Point
from .options import BundleOptions
from .residuals import projected_pixels, reprojection_residuals
from .result import BundleFit
from .triangulate import Triangulation, triangulate

__all__ = [
    "CALIBRATION_NAMES",
    "DEFAULT_FREE",
    "Block",
    "BundleFit",
    "BundleOptions",
    "Image",
    "Observations",
    "Point",
    "Triangulation",
    "bundle_adjust",
    "projected_pixels",
    "reprojection_residuals",
    "triangulate",
]

from .georef import gnss_into_block_crs, points_in, positions_in
from .io_bal import read_bal, write_bal
from .io_bundler import read_bundler, write_bundler
from .io_colmap import read_colmap, write_colmap
from .io_csv import read_csv_block, write_csv_block
from .io_formats import detect_format, read_block, write_block
from .relative_start import start_from_relative_orientation

__all__ += [
    "detect_format",
    "gnss_into_block_crs",
    "points_in",
    "positions_in",
    "read_bal",
    "read_block",
    "read_bundler",
    "read_colmap",
    "read_csv_block",
    "start_from_relative_orientation",
    "write_bal",
    "write_block",
    "write_bundler",
    "write_colmap",
    "write_csv_block",
]
