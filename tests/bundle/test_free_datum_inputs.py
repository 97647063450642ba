"""datum="free" refuses blocks whose control, GNSS or IMU fix the datum themselves, and
Block.without_datum_observations makes such a block a free network."""

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError


@pytest.fixture(scope="module")
def sim():
    return pg.simulate.uav_block(
        "FC6310", seed=1, strips=2, images_per_strip=4, tie_points_per_image=100
    )


def test_control_gnss_and_imu_are_named(sim):
    with pytest.raises(InputError, match=r"control point\(s\), GNSS positions of 8 image\(s\), "
                       r"IMU attitudes of 8 image\(s\)"):
        pg.bundle_adjust(sim.block, datum="free")
    gnss_only = sim.block.replace(
        role=np.where(sim.block.role == "control", "check", sim.block.role),
        imu=np.full_like(sim.block.imu, np.nan),
        surveyed=sim.block.survey,
    )
    with pytest.raises(InputError, match=r"has GNSS positions of 8 image\(s\), which"):
        pg.bundle_adjust(gnss_only, datum="free")


def test_without_datum_observations_is_a_free_network(sim):
    b = sim.block
    free = b.without_datum_observations()
    was_control = b.role == "control"
    assert np.all(free.role[was_control] == "check")
    assert np.all(np.isnan(free.gnss)) and np.all(np.isnan(free.imu))
    np.testing.assert_array_equal(free.surveyed_xyz[was_control], b.xyz[was_control])
    fit = pg.bundle_adjust(free, datum="free", snooping=False)
    weighted = pg.bundle_adjust(b, snooping=False)
    assert fit.converged
    # the same image residuals up to the datum: sigma0 near 1 as with the weighted datum
    assert fit.sigma0 == pytest.approx(1.0, abs=0.1)
    assert weighted.sigma0 == pytest.approx(1.0, abs=0.1)
    # the former control points are compared with their survey as check points
    assert set(fit.check["ids"]) >= set(b.point_ids[was_control].tolist())


def _two_parts(sim):
    """The block cut into its two strips sharing no points; the second strip without
    control, GNSS or IMU."""
    b = sim.block
    second = np.zeros(b.n_images, dtype=bool)
    second[b.n_images // 2 :] = True
    in_second = second[b.obs_image]
    seen_first = np.zeros(b.n_points, dtype=bool)
    seen_first[b.obs_point[~in_second]] = True
    drop = in_second & (seen_first[b.obs_point] | (b.role[b.obs_point] != "tie"))
    cut = b.select_observations(~drop).drop_weak_points(surveyed=True)
    gnss, imu = cut.gnss.copy(), cut.imu.copy()
    gnss[second], imu[second] = np.nan, np.nan
    return cut.replace(gnss=gnss, imu=imu), b.image_ids[second]


def test_a_part_without_datum_is_named_before_the_iterations(sim):
    """Before: all iterations ran, then a message blamed the calibration."""
    from photogeom.errors import DegenerateGeometryError

    cut, second = _two_parts(sim)
    first = ", ".join(map(str, second[:4].tolist()))
    with pytest.raises(DegenerateGeometryError, match=rf"2 parts .* images {first}"):
        pg.bundle_adjust(cut)
    with pytest.raises(DegenerateGeometryError, match="free network must be connected"):
        pg.bundle_adjust(cut.without_datum_observations(), datum="free")
    # each part with its own datum adjusts
    gnss = cut.gnss.copy()
    gnss[np.isin(cut.image_ids, second)] = sim.block.gnss[np.isin(sim.block.image_ids, second)]
    fit = pg.bundle_adjust(cut.replace(gnss=gnss), snooping=False)
    assert fit.converged
