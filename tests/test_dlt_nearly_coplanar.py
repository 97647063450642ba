"""The DLT of control whose height differences are below what the image coordinates resolve
is refused as coplanar, not returned as a mirrored camera or one set by the noise."""

import numpy as np
import pytest

import photogeom as pg
from photogeom import ExteriorOrientation, InteriorOrientation, project
from photogeom.errors import DegenerateGeometryError, ReflectionError

IO = InteriorOrientation(f=35.0, unit="mm")
EO = ExteriorOrientation(100.0, -50.0, 400.0, 0.02, -0.03, 0.4)
UTM = np.array([500000.0, 5000000.0, 0.0])


def _control(relief: float, seed: int, flip: bool = False):
    rng = np.random.default_rng(seed)
    g = np.c_[rng.uniform(-200, 300, 20), rng.uniform(-250, 150, 20),
              50.0 + rng.uniform(-relief / 2, relief / 2, 20)]  # fmt: skip
    im = project(g, IO, EO) + rng.normal(0.0, 0.002, (20, 2))
    if flip:
        im[:, 1] *= -1.0
    return g + UTM, im


@pytest.mark.parametrize("constrained", [False, True])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_control_flat_within_one_centimetre_is_refused_as_coplanar(seed, constrained):
    # 1 cm of relief at 350 m: at most 4e-4 mm in the image, noise 0.002 mm. Before: a
    # ReflectionError blaming left-handed image coordinates (these seeds; over 20 seeds 9
    # of them, the other 11 returned cameras 270-630 m off with std 140-2800 m)
    g, im = _control(0.01, seed)
    with pytest.raises(DegenerateGeometryError, match=r"coplanar as far as the image "
                       r"coordinates can tell: their RMS distance from the best-fitting plane"):
        pg.estimate_dlt(g, im, constrained=constrained)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_relief_that_shows_in_the_image_gives_the_camera(seed):
    g, im = _control(5.0, seed)
    fit = pg.estimate_dlt(g, im)
    std = fit.orientation_std()
    d = fit.extras["exterior"].position - EO.position - UTM
    sd = np.array([std["X0"], std["Y0"], std["Z0"]])
    assert np.all(np.abs(d) < 4.0 * sd)


def test_left_handed_image_coordinates_are_still_named_as_such():
    g, im = _control(20.0, 0, flip=True)
    with pytest.raises(ReflectionError, match="left-handed"):
        pg.estimate_dlt(g, im)
