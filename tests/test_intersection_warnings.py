"""Space intersection with rays that meet at a projection centre (the same camera
given for two images) printed numpy RuntimeWarnings with library source lines before its
error."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import DegenerateGeometryError


def test_rays_meeting_at_the_centre_raise_without_numpy_warnings():
    io = pg.InteriorOrientation(152.14, 0.0, 0.0)
    eo = pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10)
    eo2 = pg.ExteriorOrientation.from_degrees(1600, 820, 1620, -1, 2, 8)
    g = np.array([[1200.0, 900.0, 200.0], [1300.0, 1000.0, 150.0], [1400.0, 950.0, 250.0]])
    obs = np.stack([pg.project(g, io, eo), pg.project(g, io, eo2)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(DegenerateGeometryError, match="behind image"):
            pg.space_intersection(obs, [(io, eo), (io, eo)])  # image 2 with image 1's camera
