"""Finite-element residual grids: image-variant local distortions of UAV cameras.

After a bundle adjustment with Brown self-calibration, the image residuals (computed minus
observed, px) of each image are modelled by a regular grid of correction vectors with
bilinear interpolation; the field corrects image coordinates and images.

* :func:`fit_grid`, :func:`fit_grids` - the finite-element fit of one image / many images;
* :class:`ResidualGrid` - the result: nodes, standard deviations, support, statistics;
* :func:`correct_points`, :func:`correct_image`, :func:`correct_folder` - apply the field;
* :mod:`photogeom.calibration.evaluate` - residual statistics and the grid-size choice;
* :func:`save_grids`, :func:`load_grids` - the grids file (NPZ or JSON).
"""

from .grid import FiniteElementSystem, GridLayout, ResidualGrid, fit_grid, fit_grids

__all__ = [
    "FiniteElementSystem",
    "GridLayout",
    "ResidualGrid",
    "fit_grid",
    "fit_grids",
]
