"""The chain's effective redundancy when the grids are fitted to the residuals of the joint
adjustment with grids (``adjust_with_grids``, then ``fit_residual_grids`` on its final fit
and ``readjust``: the README's "both"): the first adjustment of the chain is the joint one,
whose calibration and grid nodes took up part of the noise too. Checked by a Monte Carlo of
the whole non-linear chain on fresh noise of a block without any local field: the mean of
sigma0^2 must be 1."""

import contextlib
import dataclasses
import io
import pickle
import re as re_

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import adjust_with_grids, fit_residual_grids, readjust


def _run(args):
    """The command line in this process: (exit code, stdout, stderr)."""
    from photogeom.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    code = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([str(a) for a in args])
        except SystemExit as exc:
            code = exc.code or 0
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def draws():
    """12 draws of fresh noise on one geometry: in-adjustment grids of 500 px (temporal
    constraints 0.3 px), then grids of 300 px fitted to the final fit's residuals and the
    re-adjustment; ``(final fit's block, its grids, re-adjustment, GridAdjustment)`` per
    draw."""
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=2, strips=2, images_per_strip=4, local_field=0.0)
    out = []
    for k in range(12):  # draws, not points
        ba = pg.bundle_adjust(sim.rematch(seed=100 + k), snooping=False)
        ga = adjust_with_grids(ba.block, 500.0, sigma_temporal=0.3, std=False)
        grids = fit_residual_grids(ga.fit.block, 300.0, folds=0)
        out.append((ga.fit.block, grids, readjust(ga.fit.block, grids, snooping=False), ga))
    return out


def test_sigma0_after_grids_in_and_after_the_adjustment_is_unbiased(draws):
    # before, the chain's first adjustment held the calibration and had no grid nodes:
    # mean sigma0^2 0.904 over these 12 draws (0.909 +- 0.008 over 100; effective
    # redundancy 146 on the first draw instead of 133); now 0.995 (1.001 +- 0.009 over 100)
    assert all(re.effective_redundancy is not None for _, _, re, _ in draws)
    s2 = [re.sigma0**2 for _, _, re, _ in draws]
    # one draw's sigma0^2 varies by about sqrt(2 / 133) = 0.12: the mean of 12 by 0.035
    assert abs(np.mean(s2) - 1.0) < 0.05


def test_sigma0_of_the_final_fit_of_the_adjustment_with_grids_is_unbiased(draws):
    # the final fit's residuals are the joint adjustment's: over the re-adjustment's own
    # redundancy (1021 on the first draw) the mean sigma0^2 was 0.66 over these draws, no
    # word of it; over the chain of the two (effective redundancy 697) it is 0.99
    fits = [ga.fit for *_, ga in draws]
    assert all(f.effective_redundancy["first_adjustment"] == "adjust_with_grids" for f in fits)
    assert all(f.effective_redundancy["value"] < 0.8 * f.redundancy for f in fits)
    assert all(any("estimated from these same observations" in n for n in f.notes) for f in fits)
    s2 = [f.sigma0**2 for f in fits]
    # one draw's sigma0^2 varies by about sqrt(2 / 697) = 0.054: the mean of 12 by 0.016
    assert abs(np.mean(s2) - 1.0) < 0.05


def test_readjusting_the_joint_estimate_with_its_grids_is_the_final_fit(draws, tmp_path):
    # GridAdjustment.block with GridAdjustment.grids corrects and re-adjusts as the final fit
    # did: before, its grids (no pixel positions kept) said nothing, and sigma0 was over the
    # re-adjustment's own redundancy (1021; sigma0 0.80 instead of 0.97 on this draw), with
    # no note
    ga = draws[0][3]
    again = readjust(ga.block, ga.grids, snooping=False)
    _same_chain(ga.fit, again)
    assert again.notes == ga.fit.notes
    # the same from a CSV block folder and a grids file
    pg.bundle.write_block(ga.block, tmp_path / "b", kind="csv", angle_unit="rad")
    pg.calibration.save_grids(tmp_path / "g.npz", ga.grids)
    read = readjust(
        pg.bundle.read_block(tmp_path / "b"),
        pg.calibration.load_grids(tmp_path / "g.npz"),
        snooping=False,
    )
    _same_chain(ga.fit, read)
    # other grids (or some images left uncorrected) are not the final fit: no such chain
    other = {k: g for k, g in ga.grids.items()}
    first = next(iter(other))
    other[first] = dataclasses.replace(other[first], nodes=other[first].nodes * 1.01)
    assert readjust(ga.block, other, snooping=False).effective_redundancy is None


def _same_chain(a, b) -> None:
    """``b`` took the same chain as ``a``: the same effective redundancy and sigma0, bit for
    bit (Monte-Carlo free: one draw, the same probes)."""
    assert b.effective_redundancy["value"] == a.effective_redundancy["value"]
    assert b.sigma0 == a.sigma0
    assert b.effective_redundancy["first_adjustment"] == "adjust_with_grids"


def test_copies_of_the_final_block_keep_the_joint_chain(draws):
    # before, the link was a weak dictionary keyed by the block object: a copy (replace,
    # pickle, a derived block) took the bundle adjustment of the block as the chain's first
    # adjustment, silently: effective redundancy 145.8 instead of 132.7, sigma0 0.917
    # instead of 0.961 on this draw
    block, grids, re, _ = draws[0]
    assert re.effective_redundancy["first_adjustment"] == "adjust_with_grids"
    for copy in (
        block.replace(),
        pickle.loads(pickle.dumps(block)),
        block.with_calibrations({}),
        block.with_observations(sigma=block.observations.sigma),
    ):
        _same_chain(re, readjust(copy, grids, snooping=False))
    # the record's absence is the plain chain, with a larger redundancy
    plain = readjust(block.replace(joint_adjustment=None), grids, snooping=False)
    assert plain.effective_redundancy["first_adjustment"] == "bundle_adjust"
    assert plain.effective_redundancy["value"] > re.effective_redundancy["value"] + 5
    assert plain.redundancy == re.redundancy


def test_a_csv_block_folder_keeps_the_joint_chain(draws, tmp_path):
    block, grids, re, _ = draws[0]
    pg.bundle.write_block(block, tmp_path / "rad", kind="csv", angle_unit="rad")
    _same_chain(re, readjust(pg.bundle.read_block(tmp_path / "rad"), grids, snooping=False))
    # in degrees the orientation read back differs in its last digits: the same chain,
    # sigma0 within 1e-12
    pg.bundle.write_block(block, tmp_path / "deg", kind="csv")
    again = readjust(pg.bundle.read_block(tmp_path / "deg"), grids, snooping=False)
    assert again.effective_redundancy["first_adjustment"] == "adjust_with_grids"
    assert again.effective_redundancy["value"] == pytest.approx(
        re.effective_redundancy["value"], rel=1e-12
    )
    assert again.sigma0 == pytest.approx(re.sigma0, rel=1e-12)
    # a block without the record written over the folder takes the record away
    pg.bundle.write_block(block.replace(joint_adjustment=None), tmp_path / "rad", kind="csv")
    assert not (tmp_path / "rad" / "joint_adjustment").exists()
    assert pg.bundle.read_block(tmp_path / "rad").joint_adjustment is None


def test_the_command_line_keeps_the_record_through_a_csv_block(draws, tmp_path):
    # 'bundle convert' to a CSV folder keeps it; to a format without a place for it, the
    # command warns that it is lost and how to keep it
    block, grids, re, _ = draws[0]
    pg.bundle.write_block(block, tmp_path / "blk", kind="csv", angle_unit="rad")
    code, _, err = _run(["bundle", "convert", tmp_path / "blk", tmp_path / "out", "--to",
                         "csv", "--angle-unit", "rad"])  # fmt: skip
    assert code == 0, err
    _same_chain(re, readjust(pg.bundle.read_block(tmp_path / "out"), grids, snooping=False))
    # a block without the record converted into that folder takes the record away
    pg.bundle.write_block(block.replace(joint_adjustment=None), tmp_path / "plain", kind="csv")
    code, _, err = _run(["bundle", "convert", tmp_path / "plain", tmp_path / "out", "--to",
                         "csv"])  # fmt: skip
    assert code == 0, err
    assert not (tmp_path / "out" / "joint_adjustment").exists()
    assert pg.bundle.read_block(tmp_path / "out").joint_adjustment is None
    code, _, err = _run(["bundle", "convert", tmp_path / "blk", tmp_path / "col", "--to",
                         "colmap", "--drop-extras"])  # fmt: skip
    assert code == 0, err
    assert re_.search(r"warning: .*col: a COLMAP text model has no place for the record of the "
                      r"joint adjustment.*write a CSV block folder to keep", err)  # fmt: skip
    # a conversion the format refuses gives the refusal alone, not the warning as well
    code, _, err = _run(["bundle", "convert", tmp_path / "blk", tmp_path / "b.bal", "--to",
                         "bal"])  # fmt: skip
    assert code != 0 and "--drop-extras" in err
    assert "no place for the record" not in err
    assert not (tmp_path / "b.bal").exists()


def test_a_block_changed_since_the_final_fit_says_why_the_chain_is_plain(draws):
    block, grids, _, _ = draws[0]
    moved = block.replace(exterior=block.exterior + np.array([0, 0, 0, 0, 0, 1e-6]))
    r = readjust(moved, grids, snooping=False)
    assert r.effective_redundancy["first_adjustment"] == "bundle_adjust"
    assert any("its exterior orientation differ(s) from that adjustment's final fit" in n
               for n in r.notes)  # fmt: skip


def test_an_adjustment_of_the_final_block_starts_a_chain_of_its_own(draws):
    block, _, re, _ = draws[0]
    assert block.joint_adjustment is not None
    assert re.block.joint_adjustment is None
    assert pg.bundle_adjust(block, snooping=False).block.joint_adjustment is None


def test_the_joint_estimate_with_images_left_uncorrected_keeps_the_chain(draws):
    # readjust(ga.block, ga.grids, uncorrected=[two of 8 images]): before, no chain and no
    # note, sigma0 over the re-adjustment's own redundancy (1021): mean sigma0^2 0.739 over
    # 6 draws. The uncorrected images' residuals keep their grids' part of the joint fit;
    # the chain (effective redundancy about 760, above the final fit's 700) gives 1.0
    s2 = []
    for *_, ga in draws:  # draws, not points
        ids = ga.block.image_ids.tolist()
        r = readjust(ga.block, ga.grids, uncorrected=[ids[0], ids[5]], snooping=False)
        assert r.effective_redundancy["first_adjustment"] == "adjust_with_grids"
        v = r.effective_redundancy["value"]
        assert ga.fit.effective_redundancy["value"] < v < r.redundancy
        s2.append(r.sigma0**2)
    # one draw's sigma0^2 varies by about sqrt(2 / 760) = 0.05: the mean of 12 by 0.015
    assert abs(np.mean(s2) - 1.0) < 0.05
    # grids of some images missing: they cannot be told to be the joint adjustment's own,
    # and a note says why sigma0 is over the re-adjustment's own redundancy
    ga = draws[0][3]
    ids = ga.block.image_ids.tolist()
    some = {k: g for k, g in ga.grids.items() if k != ids[0]}
    r = readjust(ga.block, some, uncorrected=[ids[0]], snooping=False)
    assert r.effective_redundancy is None
    assert any("not that adjustment's own" in n for n in r.notes)


def test_joint_uncorrected_needs_the_final_fit_of_the_joint_adjustment(draws):
    from photogeom.calibration.chain import chain_redundancy
    from photogeom.errors import InputError

    block = draws[0][0].replace(joint_adjustment=None)
    ids = block.image_ids.tolist()
    with pytest.raises(InputError, match="not the final fit of adjust_with_grids"):
        chain_redundancy(block, {}, uncorrected=ids, joint_uncorrected=ids[:1])
