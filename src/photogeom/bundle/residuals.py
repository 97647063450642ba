"""Reprojection residuals of a block's image observations (computed minus observed, pixels)."""

from __future__ import annotations

import numpy as np

from ..camera.frame_kernel import project_rows
from ..errors import DegenerateGeometryError
from .block import Block


def projected_pixels(block: Block, xyz: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Every observation's point projected into its image, in observation order.

    Parameters
    ----------
    block : Block
        Cameras, images and observations.
    xyz : numpy.ndarray, shape (p, 3), optional
        Object coordinates replacing the block's points (same order), object units.

    Returns
    -------
    uv : numpy.ndarray, shape (n, 2)
        Projected pixels (centre of the first pixel at (0, 0)), px.
    depth : numpy.ndarray, shape (n,)
        Depth of the point in front of the camera (positive in front), object units.
    """
    X = block.xyz if xyz is None else xyz
    i, j = block.obs_image, block.obs_point
    M = block.rotations()
    pr = project_rows(
        X[j],
        M[i],
        block.exterior[i, :3],
        block.calibration_matrix()[i],
        block.image_sizes()[i],
        jacobian=False,
    )
    return pr.uv, pr.depth


def reprojection_residuals(block: Block, *, behind: str = "raise") -> np.ndarray:
    """Residuals ``v = computed - observed`` (n, 2) px, in the order of ``block.observations``.

    Parameters
    ----------
    block : Block
    behind : {"raise", "nan"}
        Observations whose point lies behind its camera: raise
        :class:`~photogeom.errors.DegenerateGeometryError` naming them, or give NaN.

    Returns
    -------
    numpy.ndarray, shape (n, 2)
        Computed minus observed ``(u, v)``, px, one row per observation.
    """
    uv, depth = projected_pixels(block)
    back = ~(depth > 0)
    if np.any(back):
        if behind == "raise":
            k = np.flatnonzero(back)
            o = block.observations
            raise DegenerateGeometryError(
                f"{k.size} observation(s) have their point behind the camera, e.g. image "
                f"{o.image_ids[k[0]]} point {o.point_ids[k[0]]}: check the exterior orientation "
                "and the point coordinates (or pass behind='nan')"
            )
        uv[back] = np.nan
    return uv - block.observations.uv
