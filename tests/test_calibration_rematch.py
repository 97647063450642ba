"""Re-matched observations (``SimulatedBlock.rematch``) and the evaluation that uses them.

The study matched its corrected images anew, so its grids met measurements whose noise they
had not fitted; correcting the first observations themselves credits a grid with the noise
it fitted. These tests pin the simulator's second measurement down and show both effects.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError


def _mean_step(block) -> float:
    return float(np.mean(list(pg.calibration.model_steps(block).values())))


def _adjusted(seed: int, local_field=None):
    sim = pg.simulate.uav_block(
        "ILCE-7RM2", seed=seed, strips=2, images_per_strip=5, local_field=local_field
    )
    return sim, pg.bundle_adjust(sim.block, snooping=False)


@pytest.fixture(scope="module")
def unstable():
    return _adjusted(1)


def test_rematch_is_ideal_plus_field_plus_fresh_noise(unstable):
    sim, fit = unstable
    rem = sim.rematch(fit.block, seed=3)
    assert fit.block.same_observation_rows(rem)
    # the block's orientations, calibration and points are kept, only the pixels change
    np.testing.assert_array_equal(rem.exterior, fit.block.exterior)
    np.testing.assert_array_equal(rem.xyz, fit.block.xyz)
    np.testing.assert_array_equal(rem.observations.sigma, sim.block.observations.sigma)
    noise = rem.observations.uv - sim.ideal - sim.local
    z = noise / sim.block.observations.sigma[:, None]
    n = z.size
    # the standardised noise is N(0, 1): its variance within 5 standard errors of 1
    assert abs(float(np.mean(z * z)) - 1.0) < 5 * np.sqrt(2.0 / n)
    assert abs(float(np.mean(z))) < 5 / np.sqrt(n)
    # and independent of the first draw
    r = np.corrcoef(noise.ravel(), sim.noise.ravel())[0, 1]
    assert abs(r) < 5 / np.sqrt(n)
    # reproducible from its seed, different for another
    again = sim.rematch(fit.block, seed=3).observations.uv
    np.testing.assert_array_equal(again, rem.observations.uv)
    other = sim.rematch(fit.block, seed=4).observations.uv
    assert not np.array_equal(other, rem.observations.uv)
    # the default block is the simulated one
    np.testing.assert_array_equal(sim.rematch(seed=3).exterior, sim.block.exterior)


def test_rematch_refuses_other_rows(unstable):
    sim, fit = unstable
    keep = np.ones(fit.block.obs_image.size, dtype=bool)
    keep[::7] = False  # observations removed, as data snooping may
    fewer = fit.block.select_observations(keep)
    assert not fit.block.same_observation_rows(fewer)
    with pytest.raises(InputError, match="snooping=False"):
        sim.rematch(fewer)
    with pytest.raises(InputError, match="must be a Block"):
        sim.rematch("block.csv")
    with pytest.raises(InputError, match="same rows"):
        pg.calibration.sweep_spacings(fit, [500, 1000], rematched=fewer)


@pytest.mark.parametrize("seed", [1, 2])
def test_without_a_field_grids_only_fit_noise(seed):
    """No local field: the 100 px grids' step gain on the first observations is noise
    fitted (more than 20 %), and on re-matched observations the grids make the step worse
    than before (they add the noise they fitted)."""
    sim, fit = _adjusted(seed, local_field=0.0)
    grids = pg.calibration.fit_residual_grids(fit.block, 100, folds=0)
    before = _mean_step(fit.block)
    same = _mean_step(pg.calibration.readjust(fit.block, grids, snooping=False).block)
    rem = sim.rematch(fit.block, seed=11)
    again = _mean_step(pg.calibration.readjust(rem, grids, snooping=False).block)
    assert same < 0.8 * before
    assert again > 1.05 * before


@pytest.mark.parametrize("seed", [1, 3])
def test_a_real_field_correction_survives_rematching(seed):
    """With the unstable camera's field the grids still take a quarter or more off the
    step of re-matched observations, against the same observations uncorrected."""
    sim, fit = _adjusted(seed)
    grids = pg.calibration.fit_residual_grids(fit.block, 100, folds=0)
    rem = sim.rematch(fit.block, seed=11)
    plain = pg.bundle_adjust(rem, fix_exterior=True, free=(), snooping=False)
    corrected = pg.calibration.readjust(rem, grids, snooping=False)
    assert _mean_step(corrected.block) < 0.75 * _mean_step(plain.block)


def test_sweep_with_the_same_observations_is_the_plain_sweep(unstable):
    """``rematched`` given the adjusted block itself: the second run is the first."""
    _sim, fit = unstable
    sw = pg.calibration.sweep_spacings(fit, [300, 1000], rematched=fit.block, folds=0)
    np.testing.assert_allclose(sw["step_rematched"], sw["step"], rtol=0, atol=1e-9)
    assert sw["spacing_rematched"] == sw["spacing"]
    plain = pg.calibration.sweep_spacings(fit, [300, 1000], folds=0)
    assert "step_rematched" not in plain
    np.testing.assert_allclose(plain["step"], sw["step"], rtol=0, atol=1e-9)


def test_run_study_reports_both_evaluations():
    r = pg.calibration.run_study(
        "ILCE-7RM2", strips=2, images_per_strip=4, sweep=(300, 1000), coarse_spacing=1000
    )
    for key in ("rematched", "coarse_rematched", "coarse_share_rematched"):
        assert key in r
    assert r["sweep"]["step_rematched"].shape == r["sweep"]["step"].shape
    ev, rm = r["evaluation"], r["rematched"]
    assert rm["mean_step_before"] == ev["mean_step_before"]
    assert rm["mean_step_after"] != ev["mean_step_after"]
    off = pg.calibration.run_study(
        "ILCE-7RM2", strips=2, images_per_strip=4, sweep=None, coarse_spacing=1000, rematch=False
    )
    assert "rematched" not in off
    assert off["evaluation"]["mean_step_after"] == pytest.approx(ev["mean_step_after"], abs=1e-9)
