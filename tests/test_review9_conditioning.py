"""Review 9 (numerical conditioning and degenerate geometry)."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom import ExteriorOrientation, InteriorOrientation, project
from photogeom.errors import DegenerateGeometryError, InputError

IO_MM = InteriorOrientation(f=35.0, unit="mm")
EO_TRUE = ExteriorOrientation(100.0, -50.0, 400.0, 0.02, -0.03, 0.4)


def _three_points(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    g = np.c_[rng.uniform(-200, 300, 3), rng.uniform(-250, 150, 3), rng.uniform(0, 50, 3)]
    return g, project(g, IO_MM, EO_TRUE)


@pytest.mark.parametrize("seed", [0, 3, 7, 11])
def test_resection_with_a_repeated_point_is_three_points_not_four(seed):
    # Three distinct points and one of them listed twice: up to four exterior orientations
    # fit exactly. Before: one was returned silently (hundreds of metres off for 2/3 of
    # random cases), sigma0 ~1e-14, redundancy 2. Now: the three-point error, naming it.
    g, im = _three_points(seed)
    g4, im4 = np.r_[g, g[:1]], np.r_[im, im[:1]]
    sols = pg.p3p(g, im, IO_MM)
    if len(sols) == 1:
        fit = pg.space_resection(g4, im4, IO_MM)
        assert abs(fit.exterior.X0 - EO_TRUE.X0) < 1e-6
        return
    with pytest.raises(InputError, match=r"only 3 distinct ground positions.*initial="):
        pg.space_resection(g4, im4, IO_MM)
    fit = pg.space_resection(g4, im4, IO_MM, initial=EO_TRUE)
    assert abs(fit.exterior.X0 - EO_TRUE.X0) < 1e-6


def test_resection_many_repeats_of_three_points_never_returns_a_wrong_orientation():
    for seed in range(60):
        g, im = _three_points(seed)
        g9, im9 = np.r_[g, g, g], np.r_[im, im, im]
        try:
            fit = pg.space_resection(g9, im9, IO_MM)
        except InputError:
            continue
        assert np.hypot(fit.exterior.X0 - EO_TRUE.X0, fit.exterior.Y0 - EO_TRUE.Y0) < 1e-6


def test_resection_with_two_distinct_positions_names_the_repeat():
    g, im = _three_points(1)
    g4, im4 = np.r_[g[:2], g[:2]], np.r_[im[:2], im[:2]]
    with pytest.raises(DegenerateGeometryError, match="only 2 distinct ground position"):
        pg.space_resection(g4, im4, IO_MM)
