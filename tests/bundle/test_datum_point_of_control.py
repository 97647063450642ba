"""Control points at one point within their survey accuracy fix the block's position but
leave its scale (and, without IMU, its rotations) to their noise: the block is refused by
name instead of adjusted with a scale set by noise."""

import functools

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import DegenerateGeometryError

KW = dict(seed=3, strips=2, images_per_strip=5, gnss_sigma=None, initial_camera="truth",
          checks=4, local_field=0.0, tie_points_per_image=80)


@functools.cache
def _centre() -> np.ndarray:
    """Ground X, Y of the mean start position of the images: the middle of the block."""
    first = pg.simulate.uav_block("FC6310", gcps="none", imu_sigma_deg=None, **KW)
    return np.asarray(first.block.exterior)[:, :2].mean(axis=0)


def _block(spread: float, imu: bool = True) -> pg.bundle.Block:
    """A 2 x 5 block without GNSS, its three control points ``spread`` metres apart at the
    centre of the projection centres (survey sigmas 0.01, 0.01, 0.02 m), four check points."""
    kw = dict(KW, imu_sigma_deg=1.0 if imu else None)
    c = _centre()
    gcps = c + spread * np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    return pg.simulate.uav_block("FC6310", gcps=gcps, **kw).block


def test_control_at_one_point_within_its_survey_noise_leaves_the_scale():
    # 1 cm apart: before, with IMU attitudes, adjusted with sigma0 0.98, centres' standard
    # deviations up to 67 m and check points 3.3 m off in X (137 GSD), with no word of the
    # cause
    with pytest.raises(DegenerateGeometryError, match=r"do not fix the scale: they lie at one "
                       r"point within their accuracy \(RMS distance from their centroid"):
        pg.bundle_adjust(_block(0.01), free=())


def test_without_imu_the_rotations_are_named_too():
    with pytest.raises(DegenerateGeometryError, match=r"the scale and the 3 rotations: they "
                       r"lie at one point"):
        pg.bundle_adjust(_block(0.01, imu=False), free=())


def test_control_a_metre_apart_determines_the_scale():
    fit = pg.bundle_adjust(_block(1.0), free=())
    assert fit.converged and fit.sigma0 < 1.2
    assert np.max(fit.check["rmse"]) < 0.1  # metres
