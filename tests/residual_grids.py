"""Residual grids with given node values, shared by the tests of files and images."""

from __future__ import annotations

import numpy as np

from photogeom.calibration import GridLayout, ResidualGrid


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
