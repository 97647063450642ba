"""A start without GNSS/IMU tens of metres and degrees off: the adjustment's failure (points
behind the cameras at the start, no convergence) names the route to start values from
relative orientations, in the library's words and in the command line's."""

from __future__ import annotations

import pytest

import photogeom as pg


def _far(seed=0, **kw):
    return pg.simulate.uav_block(
        "FC300S",
        seed=seed,
        strips=2,
        images_per_strip=5,
        gnss_sigma=None,
        imu_sigma_deg=None,
        **kw,
    )


def test_points_behind_the_cameras_name_the_start_route(cli, tmp_path):
    sim = _far(initial_position_error=50.0, initial_attitude_error_deg=30.0)
    with pytest.raises(pg.DegenerateGeometryError, match="behind the camera at the start") as e:
        pg.bundle_adjust(sim.block)
    assert "photogeom.bundle.start_from_relative_orientation" in str(e.value)
    pg.bundle.write_csv_block(sim.block, tmp_path / "b")
    code, _, err = cli("bundle", "adjust", tmp_path / "b")
    assert code != 0 and "behind the camera at the start" in err
    assert "(--start relative)" in err and "start_from_relative" not in err


def test_no_convergence_names_the_start_route():
    sim = _far(1, initial_position_error=20.0, initial_attitude_error_deg=10.0)
    fit = pg.bundle_adjust(sim.block, max_iterations=3)
    assert not fit.converged
    (note,) = [n for n in fit.notes if n.startswith("not converged: 3 iterations reached")]
    assert "start_from_relative_orientation" in note and "--start relative" in note


def test_check_points_lost_by_a_run_that_stopped_blame_the_run():
    # the cameras where the run stopped cannot intersect a check point: before, an
    # InputError blamed the observations
    sim = _far(2, initial_position_error=20.0, initial_attitude_error_deg=10.0)
    with pytest.raises(pg.ConvergenceError, match="cannot be triangulated") as e:
        pg.bundle_adjust(sim.block, max_iterations=3)
    assert "stopped (not converged: 3 iterations reached)" in str(e.value)
    assert "start_from_relative_orientation" in str(e.value)
