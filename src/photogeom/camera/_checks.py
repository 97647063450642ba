"""Check points of the camera estimators: image residuals of points not in the estimate."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..adjust import Fit
from ..validation import as_points, check_same_length


def with_check_points(
    fit: Fit,
    project: Callable[[np.ndarray], np.ndarray],
    check_ground,
    check_image,
    check_ids,
    observed_to_image: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Fit:
    """``fit`` with the residuals ``project(check_ground) - check_image`` (computed minus
    observed, image units) of check points; ``fit`` itself when none are given.

    Parameters
    ----------
    project : callable
        Ground points (n, 3) -> image points (n, 2) of the estimated camera.
    check_ground, check_image : array_like, shape (n, 3) and (n, 2), or None
    check_ids : sequence or None
    observed_to_image : callable, optional
        Applied to the validated ``check_image`` first (e.g. pixel -> image coordinates)
        when the observations are not in the unit of ``project``.
    """
    if check_ground is None and check_image is None:
        return fit
    cg = as_points(check_ground, 3, "check ground points")
    ci = as_points(check_image, 2, "check image points")
    check_same_length(cg, ci, "check ground points", "check image points")
    if observed_to_image is not None:
        ci = observed_to_image(ci)
    return fit.with_checks(project(cg) - ci, check_ids)
