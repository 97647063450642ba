"""The best estimator's error of a simulated local field (``field_bound``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError
from photogeom.simulate.fields import LocalDistortionField


def _block(**kw):
    return pg.simulate.uav_block(
        "FC300S",
        seed=11,
        strips=2,
        images_per_strip=3,
        tie_points_per_image=150,
        local_field=0.5,
        local_field_modes=2,
        **kw,
    )


def test_the_expected_error_is_the_spread_over_fields_and_noise_drawn_like_the_simulators():
    """Fields and noise drawn again from the simulator's distribution, the geometry kept: the
    RMS of the posterior mean's error over 40 draws matches the expected error (posterior
    covariance), and the fields' RMS the prior."""
    sim = _block()
    F0, b = sim.field, sim.block
    rng = np.random.default_rng(5)
    sigma = b.observations.sigma
    expected = pg.calibration.field_bound(sim)
    err2, fld2 = [], []
    for _ in range(40):
        F = LocalDistortionField.random(
            rng, F0.image_ids, F0.width, F0.height, rms=0.5, modes=2, correlation=0.9
        )
        local = F.rows(b.obs_image, sim.ideal)
        noise = rng.normal(0.0, 1.0, sim.ideal.shape) * sigma[:, None]
        r = pg.calibration.field_bound(dataclasses.replace(sim, field=F, local=local, noise=noise))
        assert r["expected_ratio"] == pytest.approx(expected["expected_ratio"], rel=1e-9)
        err2.append(r["error_rms"] ** 2)
        fld2.append(r["realised_field_rms"] ** 2)
    e_exp = expected["expected_ratio"] * expected["field_rms"]
    assert np.sqrt(np.mean(err2)) == pytest.approx(e_exp, rel=0.05)
    assert np.sqrt(np.mean(fld2)) == pytest.approx(expected["field_rms"], rel=0.12)
    assert 0.0 < expected["expected_ratio"] < 1.0
    assert expected["coefficients"] == 6 * 2 * 24 and expected["images"] == 6


def test_observations_that_say_nothing_leave_the_prior():
    """With 1000 px of measurement noise the observations do not inform the field: the best
    estimate is the prior mean (zero), its error the field itself."""
    r = pg.calibration.field_bound(_block(sigma=1000.0, gcp_sigma=1000.0))
    assert r["expected_ratio"] == pytest.approx(1.0, abs=1e-3)


def test_a_block_without_a_field_is_refused():
    sim = pg.simulate.uav_block("FC300S", seed=11, strips=2, images_per_strip=3, local_field=0.0)
    with pytest.raises(InputError, match="no local field"):
        pg.calibration.field_bound(sim)
