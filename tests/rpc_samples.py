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


def unit_rpc_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coefficients of the simplest RPC: line = normalised latitude, sample = normalised
    longitude, denominators 1.

    Returns
    -------
    line_num, den, samp_num : ndarray, shape (20,)
        Line numerator, denominator (for line and sample) and sample numerator, in the
        standard term order.
    """
    line_num = np.zeros(20)
    line_num[2] = 1.0
    den = np.zeros(20)
    den[0] = 1.0
    samp_num = np.zeros(20)
    samp_num[1] = 1.0
    return line_num, den, samp_num
