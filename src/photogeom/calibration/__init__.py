"""Finite-element residual grids: image-variant local distortions of UAV cameras.

After a bundle adjustment with Brown self-calibration, the image residuals (computed minus
observed, px) of each image are modelled by a regular grid of correction vectors with
bilinear interpolation; the field corrects image coordinates and images.

* :func:`fit_grid`, :func:`fit_grids` - the finite-element fit of one image / many images;
* :class:`ResidualGrid` - the result: nodes, standard deviations, support, statistics;
* :func:`correct_points`, :func:`correct_observations`, :func:`correct_image`,
  :func:`correct_image_file`, :func:`correct_folder` - apply the field;
* :func:`compare_residuals`, :func:`choose_spacing`, :func:`most_frequent_spacing` -
  evaluation on arrays (:mod:`photogeom.calibration.evaluate`);
* :func:`save_grids`, :func:`load_grids` - the grids file (NPZ or JSON);
* :func:`fit_residual_grids`, :func:`readjust`, :func:`model_steps` - the block level
  (:mod:`photogeom.calibration.blocks`, :mod:`photogeom.calibration.steps`);
  :func:`correct_observations` takes a Block or arrays per image;
* :func:`adjust_with_grids` - the grids estimated inside the bundle adjustment
  (:mod:`photogeom.calibration.in_adjustment`), :func:`compare_in_adjustment` - against
  the post-processing on a simulated block;
* :func:`field_bound` - on a simulated block, the error of the best estimator of the local
  field (the floor of any method; :mod:`photogeom.calibration.field_bound`).
"""

from .blocks import block_residuals, correct_block_observations, fit_residual_grids, readjust
from .correction import correct_image, correct_points, field_at_pixels
from .dispatch import correct_observations
from .evaluate import (
    choose_spacing,
    compare_residuals,
    min_max_normalise,
    most_frequent_spacing,
    residual_statistics,
)
from .field_bound import field_bound
from .grid import FiniteElementSystem, GridLayout, ResidualGrid, fit_grid, fit_grids
from .gridfile import load_grids, save_grids
from .images import FolderResult, correct_folder, correct_image_file
from .in_adjustment import GridAdjustment, adjust_with_grids
from .steps import StereoModels, image_overlap, model_steps, stereo_models
from .study import (
    compare_in_adjustment,
    evaluate_readjustment,
    field_recovery,
    run_study,
    sweep_spacings,
    visible_field,
    visible_recovery,
)

__all__ = [
    "FiniteElementSystem",
    "FolderResult",
    "GridLayout",
    "ResidualGrid",
    "choose_spacing",
    "compare_residuals",
    "correct_folder",
    "correct_image",
    "correct_image_file",
    "correct_observations",
    "correct_points",
    "field_at_pixels",
    "field_bound",
    "fit_grid",
    "fit_grids",
    "load_grids",
    "min_max_normalise",
    "most_frequent_spacing",
    "residual_statistics",
    "save_grids",
]
__all__ += [
    "GridAdjustment",
    "StereoModels",
    "adjust_with_grids",
    "block_residuals",
    "compare_in_adjustment",
    "correct_block_observations",
    "evaluate_readjustment",
    "field_recovery",
    "fit_residual_grids",
    "image_overlap",
    "model_steps",
    "readjust",
    "run_study",
    "stereo_models",
    "sweep_spacings",
    "visible_field",
    "visible_recovery",
]
