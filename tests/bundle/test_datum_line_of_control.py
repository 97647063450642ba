"""Control points on one line within their survey accuracy leave the roll about the line
undetermined: the block is refused by name instead of adjusted to a roll set by noise."""

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import DegenerateGeometryError


def _block(offsets: float = 0.0, imu: bool = False) -> pg.bundle.Block:
    """A flat 3 x 6 block without GNSS whose five control points lie on the diagonal of the
    projection centres' rectangle, alternately ``offsets`` metres to either side of it."""
    kw = dict(seed=3, strips=3, images_per_strip=6, gnss_sigma=None, terrain="flat",
              initial_camera="truth", checks=0, local_field=0.0)
    kw["imu_sigma_deg"] = 1.0 if imu else None
    first = pg.simulate.uav_block("FC300S", gcps="none", **kw)
    c = np.asarray(first.block.exterior)[:, :2]
    lo, hi = c.min(axis=0), c.max(axis=0)
    along = lo + (hi - lo) * np.linspace(0.0, 1.0, 5)[:, None]
    normal = np.array([-(hi - lo)[1], (hi - lo)[0]]) / np.linalg.norm(hi - lo)
    gcps = along + offsets * np.array([0, 1, -1, 1, 0])[:, None] * normal
    return pg.simulate.uav_block("FC300S", gcps=gcps, **kw).block


def test_control_on_a_line_within_its_survey_noise_is_a_named_datum_defect():
    # survey sigmas 0.01, 0.01, 0.02 m: the points' distances from their line are noise;
    # before, the block was adjusted without convergence (100 iterations), centres
    # +-50 m, angles +-1 rad and check heights 1.2 m off, with no word of the cause
    with pytest.raises(DegenerateGeometryError, match=r"rotation about the line.*within their "
                       r"accuracy \(RMS distance from the line 0\.0\d+, [\d.]+ times"):
        pg.bundle_adjust(_block())


def test_control_20_m_off_its_line_determines_the_roll():
    fit = pg.bundle_adjust(_block(offsets=20.0), free=())
    assert fit.converged
    assert fit.sigma0 < 1.3
    assert np.max(fit.exterior_std[:, 3:]) < 0.01  # degrees
    assert np.max(fit.exterior_std[:, :3]) < 0.1  # metres


def test_imu_attitudes_fix_the_roll_of_a_line_of_control():
    fit = pg.bundle_adjust(_block(imu=True), free=())
    assert fit.converged
