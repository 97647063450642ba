"""Residual grids with given node values and observations that hold given fields, shared by
the tests of grid files, images and grids in the adjustment."""

from __future__ import annotations

import numpy as np

from photogeom.calibration import GridLayout, ResidualGrid
from photogeom.calibration.grid import evaluate_nodes


def grid_with_nodes(layout: GridLayout, nodes: np.ndarray) -> ResidualGrid:
    """A grid holding ``nodes`` (``(*layout.shape, 2)`` px) and neutral statistics: no
    supported node, sigma0 1, RMS 1 before and after."""
    zero = np.zeros(layout.shape)
    return ResidualGrid(
        layout=layout,
        nodes=np.asarray(nodes, dtype=float),
        sigma0=1.0,
        redundancy=1,
        sigma_obs=np.ones(1),
        sigma_constraint=1.0,
        support=zero > 0,
        counts=zero.astype(int),
        rms_before=1.0,
        rms_after=1.0,
    )


def observe(truth, ideal: np.ndarray, fields) -> np.ndarray:
    """Observations ``u`` with ``u + r(u) = ideal`` for modelled residual fields ``r``
    (``fields[i]`` evaluates image row ``i`` of ``truth``), by fixed-point iteration."""
    uv = ideal.copy()
    for _ in range(50):
        new = ideal.copy()
        for i in range(truth.n_images):  # images, not points
            sel = truth.obs_image == i
            new[sel] = ideal[sel] - fields[i](uv[sel])
        if np.max(np.abs(new - uv)) < 1e-12:
            break
        uv = new
    return new


def node_field(layout: GridLayout, nodes: np.ndarray):
    """The bilinear field of ``nodes`` on ``layout``, as a function of pixels (n, 2)."""
    return lambda uv: evaluate_nodes(layout, nodes, uv)
