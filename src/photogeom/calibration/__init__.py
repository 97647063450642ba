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

# Each public name is imported from its module on first use (module-level __getattr__), so
# that a command that only applies or fits grids does not import the block readers and the
# bundle adjustment the block-level functions need; ``from photogeom.calibration import X``
# and ``photogeom.calibration.X`` work as for an eager import.
_LAZY: dict[str, str] = {
    "block_residuals": ".blocks",
    "correct_block_observations": ".blocks",
    "fit_residual_grids": ".blocks",
    "readjust": ".blocks",
    "correct_image": ".correction",
    "correct_points": ".correction",
    "field_at_pixels": ".correction",
    "correct_observations": ".dispatch",
    "choose_spacing": ".evaluate",
    "compare_residuals": ".evaluate",
    "min_max_normalise": ".evaluate",
    "most_frequent_spacing": ".evaluate",
    "residual_statistics": ".evaluate",
    "field_bound": ".field_bound",
    "FiniteElementSystem": ".grid",
    "GridLayout": ".grid",
    "ResidualGrid": ".grid",
    "fit_grid": ".grid",
    "fit_grids": ".grid",
    "load_grids": ".gridfile",
    "save_grids": ".gridfile",
    "FolderResult": ".images",
    "correct_folder": ".images",
    "correct_image_file": ".images",
    "GridAdjustment": ".in_adjustment",
    "adjust_with_grids": ".in_adjustment",
    "StereoModels": ".steps",
    "image_overlap": ".steps",
    "model_steps": ".steps",
    "stereo_models": ".steps",
    "compare_in_adjustment": ".study",
    "evaluate_readjustment": ".study",
    "field_recovery": ".study",
    "run_study": ".study",
    "sweep_spacings": ".study",
    "visible_field": ".study",
    "visible_recovery": ".study",
}


def __getattr__(name: str):
    import importlib

    if name not in _LAZY and not name.startswith("__"):
        # a submodule not imported yet (``photogeom.calibration.grid``)
        try:
            return importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


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
