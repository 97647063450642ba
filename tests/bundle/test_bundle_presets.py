"""The bundle adjustment on the simulator's preset blocks: the full Metashape model, and a
plain statement where the geometry cannot determine a parameter."""

import numpy as np
import pytest

import photogeom as pg

FULL = ("f", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")


@pytest.mark.parametrize("camera", ["FC300S", "FC6310", "ILCE-7RM2"])
def test_full_metashape_model_converges_on_every_preset(camera):
    sim = pg.simulate.uav_block(camera, seed=1, local_field=0.0)
    res = pg.bundle_adjust(sim.block, free=FULL, snooping=False)
    assert res.converged
    assert res.sigma0 == pytest.approx(1.0, abs=0.15)
    g = next(iter(res.calibration))
    true = sim.truth.calibrations[0]
    for name in ("f", "cx", "cy"):
        err = res.calibration[g][name] - getattr(true, name)
        assert abs(err) < 5 * res.calibration_std[g][name] + 1e-9, (name, err)
    # check points within a few GSD
    assert np.all(res.check["rmse_gsd"] < 5)


def test_flat_block_without_gnss_says_the_focal_length_is_undetermined():
    sim = pg.simulate.uav_block(
        "FC300S",
        seed=2,
        terrain="flat",
        gnss_sigma=None,
        imu_sigma_deg=None,
        attitude_jitter_deg=0.2,
    )
    res = pg.bundle_adjust(sim.block, snooping=False)
    assert any("focal length is poorly determined" in n for n in res.notes)
