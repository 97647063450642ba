"""The redundancy of the chain adjustment - residual grids - re-adjustment
(``photogeom.calibration.chain``) and the sigma0 of ``readjust`` computed with it.

Checked against what does not come from the trace's code: the first adjustment's own
redundancy (no grid: the chain's residuals are the first adjustment's), and a Monte Carlo of
the whole non-linear chain on fresh noise (blocks without any local field, where the
observations' sigmas are the truth: the mean of sigma0^2 must be 1)."""

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import fit_residual_grids, readjust
from photogeom.calibration.chain import chain_redundancy


@pytest.fixture(scope="module")
def ilce():
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4, local_field=0.0)
    ba = pg.bundle_adjust(sim.block)
    return sim, ba, fit_residual_grids(ba.block, 200, folds=0)


def test_without_grids_the_chain_has_the_first_adjustments_redundancy(ilce):
    # (I - H3)(I - H1) = I - H1: re-triangulating the points of the first adjustment with its
    # cameras held changes no residual, so the trace is n - u of the first adjustment
    _, ba, grids = ilce
    r = chain_redundancy(ba.block, grids, uncorrected=ba.block.image_ids.tolist(), exact=True)
    assert r["method"] == "exact"
    assert r["value"] == pytest.approx(ba.redundancy, abs=1e-6)


def test_estimate_agrees_with_the_exact_trace(ilce):
    _, ba, grids = ilce
    exact = chain_redundancy(ba.block, grids, exact=True)
    est = chain_redundancy(ba.block, grids, probes=32, seed=5)
    assert est["method"] == "estimated" and est["seed"] == 5
    # 32 probes leave 2 % relative error on this redundancy: more (up to 64) for 1 %
    assert est["probes"] == 64
    # the grids take up most of the re-adjustment's count (946 here)
    assert exact["value"] < 0.3 * (ba.redundancy + 56)
    assert abs(est["value"] - exact["value"]) < 4 * est["std"]
    assert est["std"] < 0.02 * exact["value"]  # about sqrt(2 / (K r)) relative
    again = chain_redundancy(ba.block, grids, probes=32, seed=5)
    assert again["value"] == est["value"]  # seeded


@pytest.mark.parametrize(
    ("camera", "spacing", "draws"), [("FC300S", 200, 8), ("ILCE-7RM2", 500, 12)]
)
def test_readjusted_sigma0_is_unbiased_over_fresh_noise(camera, spacing, draws):
    # the whole chain, non-linear, on fresh noise of one geometry: the in-sample sigma0 was
    # 0.5-0.7 here (sigma0^2 0.25-0.5); over the chain's redundancy E[sigma0^2] = 1
    sim = pg.simulate.uav_block(camera, seed=2, strips=2, images_per_strip=4, local_field=0.0)
    s2 = []
    for k in range(draws):  # draws, not points
        ba = pg.bundle_adjust(sim.rematch(seed=100 + k))
        grids = fit_residual_grids(ba.block, spacing, folds=0)
        re = readjust(ba.block, grids, snooping=False)
        assert re.effective_redundancy is not None
        assert re.effective_redundancy["value"] < re.redundancy
        s2.append(re.sigma0**2)
    # one draw's sigma0^2 varies by about sqrt(2 / r) (r 150-550): the mean by 0.02-0.035
    assert abs(np.mean(s2) - 1.0) < 0.1


def test_readjust_reports_the_chain_in_its_result(ilce):
    _, ba, grids = ilce
    re = readjust(ba.block, grids, snooping=False, redundancy_probes=4, redundancy_seed=9)
    eff = re.effective_redundancy
    assert (eff["method"], eff["seed"]) == ("estimated", 9)
    # batches of 4 probes until the standard error is 1 % of the estimate (or 64 probes)
    assert eff["probes"] % 4 == 0 and 4 < eff["probes"] <= 64
    assert eff["std"] <= 0.01 * eff["value"] or eff["probes"] == 64
    vtpv = re.chi2["statistic"]
    assert re.sigma0 == pytest.approx(np.sqrt(vtpv / eff["value"]))
    assert re.chi2["dof"] == pytest.approx(eff["value"])
    d = re.to_dict()
    assert d["effective_redundancy"]["value"] == pytest.approx(eff["value"])
    assert d["redundancy"] == re.redundancy  # the plain count stays
    assert "effective redundancy of the chain" in re.summary()


def test_observations_measured_again_keep_the_plain_redundancy(ilce):
    sim, ba, grids = ilce
    again = readjust(sim.rematch(ba.block, seed=3), grids, snooping=False)
    assert again.effective_redundancy is None
    assert again.chi2["dof"] == again.redundancy
    assert again.sigma0 == pytest.approx(np.sqrt(again.chi2["statistic"] / again.redundancy))


def test_a_block_not_adjusted_keeps_the_plain_redundancy_and_says_why():
    # the bundled 3-image block before adjustment: its parameters are not determined at its
    # start values, so there is no first adjustment to linearise (readjust raised
    # "normal matrix of the first adjustment is not positive definite")
    from pathlib import Path

    from photogeom import datasets
    from photogeom.calibration.blocks import NO_CHAIN_NOTE

    bal = Path(datasets.__file__).parent / "data" / "bundle" / "dubrovnik-3-7-pre.txt"
    block = pg.bundle.read_block(bal)
    grids = fit_residual_grids(block, 500, folds=0)
    re = readjust(block, grids, snooping=False)
    assert re.effective_redundancy is None
    assert re.chi2["dof"] == re.redundancy
    (note,) = [n for n in re.notes if n.startswith(NO_CHAIN_NOTE)]
    assert "first adjustment" in note and "not positive definite" in note
