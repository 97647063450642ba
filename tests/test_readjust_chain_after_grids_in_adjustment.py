"""The chain's effective redundancy when the grids are fitted to the residuals of the joint
adjustment with grids (``adjust_with_grids``, then ``fit_residual_grids`` on its final fit
and ``readjust``: the README's "both"): the first adjustment of the chain is the joint one,
whose calibration and grid nodes took up part of the noise too. Checked by a Monte Carlo of
the whole non-linear chain on fresh noise of a block without any local field: the mean of
sigma0^2 must be 1."""

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import adjust_with_grids, fit_residual_grids, readjust


@pytest.fixture(scope="module")
def draws():
    """12 draws of fresh noise on one geometry: in-adjustment grids of 500 px (temporal
    constraints 0.3 px), then grids of 300 px fitted to the final fit's residuals and the
    re-adjustment; ``(final fit's block, its grids, re-adjustment)`` per draw."""
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=2, strips=2, images_per_strip=4, local_field=0.0)
    out = []
    for k in range(12):  # draws, not points
        ba = pg.bundle_adjust(sim.rematch(seed=100 + k), snooping=False)
        ga = adjust_with_grids(ba.block, 500.0, sigma_temporal=0.3, std=False)
        grids = fit_residual_grids(ga.fit.block, 300.0, folds=0)
        out.append((ga.fit.block, grids, readjust(ga.fit.block, grids, snooping=False)))
    return out


def test_sigma0_after_grids_in_and_after_the_adjustment_is_unbiased(draws):
    # before, the chain's first adjustment held the calibration and had no grid nodes:
    # mean sigma0^2 0.904 over these 12 draws (0.909 +- 0.008 over 100; effective
    # redundancy 146 on the first draw instead of 133); now 0.995 (1.001 +- 0.009 over 100)
    assert all(re.effective_redundancy is not None for _, _, re in draws)
    s2 = [re.sigma0**2 for _, _, re in draws]
    # one draw's sigma0^2 varies by about sqrt(2 / 133) = 0.12: the mean of 12 by 0.035
    assert abs(np.mean(s2) - 1.0) < 0.05


def test_a_copy_of_the_final_block_is_a_plain_adjusted_block(draws):
    # a copy (as one written and read again) does not say where it came from: its chain's
    # first adjustment is the bundle adjustment of that block, with a larger redundancy
    block, grids, re = draws[0]
    plain = readjust(block.replace(), grids, snooping=False)
    assert plain.effective_redundancy["value"] > re.effective_redundancy["value"] + 5
    assert plain.redundancy == re.redundancy
