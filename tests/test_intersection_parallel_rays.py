"""Space intersection from images taken at (nearly) one position: the points that fall
behind a camera are named as nearly parallel rays, not as wrong orientations."""

import numpy as np
import pytest

import photogeom as pg
from photogeom import ExteriorOrientation, InteriorOrientation, project
from photogeom.errors import DegenerateGeometryError

IO = InteriorOrientation(f=35.0, unit="mm")
UTM = np.array([500000.0, 5000000.0, 0.0])


def _pair(base: float, seed: int = 3):
    rng = np.random.default_rng(seed)
    g = np.c_[rng.uniform(-100, 100, 5), rng.uniform(-100, 100, 5), rng.uniform(0, 30, 5)]
    eos = [ExteriorOrientation(b, 0.0, 500.0, 0.01, 0.02, 0.1) for b in (0.0, base)]
    obs = np.stack([project(g, IO, e) + rng.normal(0.0, 0.002, (5, 2)) for e in eos])
    cams = [(IO, ExteriorOrientation(*(e.position + UTM), e.omega, e.phi, e.kappa)) for e in eos]
    return obs, cams


@pytest.mark.parametrize("base", [0.0, 1e-6, 1e-3])
def test_points_behind_from_nearly_one_position_are_named_as_parallel_rays(base):
    # before: "... fall behind image 0 ...: check the orientations and the point
    # correspondences", though both were right
    obs, cams = _pair(base)
    with pytest.raises(DegenerateGeometryError, match=r"fall behind image \d .*their rays are "
                       r"nearly parallel \(they meet at [\d.e-]+ deg at most\)"):
        pg.space_intersection(obs, cams)


def test_points_behind_with_a_real_base_still_point_to_the_orientations():
    obs, cams = _pair(100.0)
    io, eo = cams[1]
    cams[1] = (io, ExteriorOrientation(*eo.position, eo.omega + np.pi, eo.phi, eo.kappa))
    with pytest.raises(DegenerateGeometryError, match="check the orientations"):
        pg.space_intersection(obs, cams)
