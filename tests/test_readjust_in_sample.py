"""``readjust`` on the observations its grids were fitted to computes its sigma0 over the
chain's redundancy and notes that its standard deviations are in-sample (too small), and
says nothing on observations measured again, where they are valid (a block without any
local field: sigma0 ~ 1 is the truth)."""

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import fit_residual_grids, readjust
from photogeom.calibration.blocks import IN_SAMPLE_NOTE


@pytest.fixture(scope="module")
def fitted():
    sim = pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=4, local_field=0.0)
    ba = pg.bundle_adjust(sim.block)
    return sim, ba, fit_residual_grids(ba.block, 200, folds=0)


def test_in_sample_readjustment_is_noted_and_its_sigma0_counts_the_chain(fitted):
    _, ba, grids = fitted
    re = readjust(ba.block, grids, snooping=False)
    assert IN_SAMPLE_NOTE in re.notes
    # no field at all: the first adjustment's sigma0 is about 1, and so is the re-adjustment's
    # over the chain's redundancy (over its own count it was 0.72: in-sample)
    assert 0.9 < ba.sigma0 < 1.1
    assert 0.9 < re.sigma0 < 1.1
    assert re.effective_redundancy["value"] < 0.5 * re.redundancy


def test_observations_measured_again_are_not_noted_and_their_sigma0_is_valid(fitted):
    sim, ba, grids = fitted
    again = readjust(sim.rematch(ba.block, seed=3), grids, snooping=False)
    assert IN_SAMPLE_NOTE not in again.notes
    assert 0.95 < again.sigma0 < 1.35  # the grids' own error adds to the fresh noise


def test_grids_without_their_positions_say_nothing(fitted):
    _, ba, grids = fitted
    blind = {k: g.__class__(**{**g.__dict__, "uv": None}) for k, g in grids.items()}
    assert all(g.uv is None for g in blind.values())
    re = readjust(ba.block, blind, snooping=False)
    assert IN_SAMPLE_NOTE not in re.notes
    assert re.effective_redundancy is None
    # the same residuals over the plain count: the in-sample sigma0, not found out
    known = readjust(ba.block, grids, snooping=False)
    np.testing.assert_allclose(re.chi2["statistic"], known.chi2["statistic"])
    assert re.sigma0 < 0.8 < known.sigma0
