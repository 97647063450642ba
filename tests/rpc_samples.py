"""Ground and image points of the bundled IKONOS RPC, shared by the tests of RPC fits."""

from __future__ import annotations

import numpy as np

import photogeom as pg
from photogeom.rpc import RPC

IKONOS = RPC.from_file(pg.datasets.path("ikonos"))


def ikonos_points(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points drawn uniformly over the IKONOS image and its height range.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draws (columns, rows, then heights).
    n : int
        Number of points.

    Returns
    -------
    ground : ndarray, shape (n, 3)
        Longitude and latitude (degrees) and height (m) where the vendor RPC localises each
        image point at its drawn height.
    image : ndarray, shape (n, 2)
        The drawn columns and rows (px).
    """
    c0, c1, r0, r1 = IKONOS.image_bounds
    cols, rows = rng.uniform(c0, c1, n), rng.uniform(r0, r1, n)
    h = rng.uniform(*IKONOS.height_range, n)
    lon, lat = IKONOS.localize(cols, rows, h)
    return np.column_stack([lon, lat, h]), np.column_stack([cols, rows])
