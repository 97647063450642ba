"""Residual grids of a whole block: fit, correct, re-adjust, steps (small simulated blocks)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError, TooFewPointsError


def _rms(v):
    return float(np.sqrt(np.mean(np.sum(v * v, axis=1))))


@pytest.fixture(scope="module")
def unstable():
    """A small block of the study's unstable camera, adjusted, with its grids."""
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=5)
    fit = pg.bundle_adjust(sim.block, snooping=False)
    grids = pg.calibration.fit_residual_grids(fit.block, spacing=100, folds=0)
    return sim, fit, grids


def test_contract_names():
    cal = pg.calibration
    for name in ("fit_residual_grids", "correct_observations", "readjust", "model_steps"):
        assert callable(getattr(cal, name))
        assert name in cal.__all__


def test_grids_per_image_from_tie_residuals(unstable):
    _, fit, grids = unstable
    b = fit.block
    assert list(grids) == b.image_ids.tolist()
    w, h = (int(x) for x in b.image_sizes()[0])
    r = pg.bundle.reprojection_residuals(b)
    tie = b.role[b.obs_point] == "tie"
    for i, iid in enumerate(b.image_ids.tolist()):
        g = grids[iid]
        assert g.image_size == (w, h)
        assert g.spacing == 100
        m = tie & (b.obs_image == i)
        # the grid was fitted to exactly this image's tie-point residuals
        assert g.sigma_obs.size == int(m.sum())
        assert g.rms_before == pytest.approx(_rms(r[m]))


def test_correct_observations_block_and_arrays_agree(unstable):
    _, fit, grids = unstable
    b = fit.block
    b2 = pg.calibration.correct_observations(b, grids)
    assert isinstance(b2, pg.bundle.Block)
    per = {iid: b.observations.uv[b.obs_image == i] for i, iid in enumerate(b.image_ids.tolist())}
    arr = pg.calibration.correct_observations(per, grids)
    for i, iid in enumerate(b.image_ids.tolist()):
        m = b.obs_image == i
        np.testing.assert_array_equal(b2.observations.uv[m], arr[iid])
        # uv + r(uv): the modelled residual added
        uv = b.observations.uv[m]
        np.testing.assert_allclose(arr[iid] - uv, grids[iid].evaluate(uv))
    np.testing.assert_array_equal(b2.xyz, b.xyz)
    np.testing.assert_array_equal(b2.exterior, b.exterior)


def test_readjust_fixes_orientation_and_reduces_residuals_and_steps(unstable):
    sim, fit, grids = unstable
    re = pg.calibration.readjust(fit.block, grids, snooping=False)
    np.testing.assert_allclose(re.block.exterior, fit.block.exterior, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        re.block.calibration_matrix(), fit.block.calibration_matrix(), rtol=1e-14
    )
    ev = pg.calibration.evaluate_readjustment(fit, re, sim=sim)
    assert ev["residuals"]["block"]["reduction_rms"] > 0.5
    assert ev["mean_step_before"] > 2.0  # the unstable camera's strong field: a visible step
    assert ev["mean_step_after"] < 0.5 * ev["mean_step_before"]
    assert set(ev["check_after"]) == {"errors", "rmse", "rmse_gsd"}


def test_readjust_stops_at_the_minimum_to_rounding(unstable):
    """Only the points move (one 3 x 3 system each): the minimum is reached in a few steps,
    then the step's predicted decrease is rounding; the damping was raised nine times
    until the step fell below xtol (12 iterations, each a factorisation)."""
    _, fit, grids = unstable
    re = pg.calibration.readjust(fit.block, grids, snooping=False)
    assert re.converged and re.iterations <= 4
    assert "predicted decrease below ftol" in re.message
    assert all(a > b for a, b in zip(re.cost_history, re.cost_history[1:]))


def test_field_recovered_where_supported():
    """Residuals against the true orientation: the grid matches the true local field."""
    sim = pg.simulate.uav_block(
        "ILCE-7RM2",
        seed=3,
        strips=1,
        images_per_strip=4,
        tie_points_per_image=600,
        gcps="none",
        checks=0,
        sigma=0.1,
    )
    block = sim.truth.with_observations(uv=sim.observed)  # residuals = -(field + noise)
    grids = pg.calibration.fit_residual_grids(block, 200, sigma_constraint=0.1, folds=0)
    rec = pg.calibration.field_recovery(sim, grids)
    assert rec["block"]["field_rms"] > 0.5
    for iid, r in rec["images"].items():
        assert r["nodes"] > 100
        assert r["ratio"] < 0.2, iid


def test_model_steps_zero_on_the_truth_and_overlap_rule():
    sim = pg.simulate.uav_block("FC300S", seed=2, strips=2, images_per_strip=6, local_field=0.0)
    truth = sim.truth  # ideal observations, true cameras: both models agree exactly
    sm = pg.calibration.stereo_models(truth)
    assert len(sm.strips) == 2
    assert sm.offsets == [2, 2]  # 80 % forward overlap: every second image gives ~60 %
    assert all(abs(o - 0.6) < 0.1 for o in sm.model_overlap)
    steps, info = pg.calibration.model_steps(truth, details=True)
    assert set(steps) == {(a, b) for a, b, _ in sm.triples}
    assert max(steps.values()) < 1e-6
    assert all(v["n"] >= 3 for v in info.values())
    # a height error of one image shows as a step between its two models
    ext = truth.exterior.copy()
    ext[2, 2] += 0.5  # image 2 raised by 0.5 m
    steps2 = pg.calibration.model_steps(truth.replace(exterior=ext))
    assert steps2[(0, 2)] > 1.0


def test_seventy_percent_overlap_uses_neighbours():
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=2, strips=1, images_per_strip=5)
    sm = pg.calibration.stereo_models(sim.truth)
    assert sm.offsets == [1]
    assert [t[:2] for t in sm.triples] == [(0, 1), (1, 2), (2, 3)]


def test_bad_input(unstable):
    _, fit, grids = unstable
    b = fit.block
    with pytest.raises(InputError, match="positive"):
        pg.calibration.fit_residual_grids(b, spacing=0)
    with pytest.raises(InputError, match="larger than the image"):
        pg.calibration.fit_residual_grids(b, spacing=9000)
    # image 0 keeps only 2 tie observations: too few for its grid, named
    tie = b.role[b.obs_point] == "tie"
    rows0 = np.flatnonzero(tie & (b.obs_image == 0))
    keep = np.ones(b.n_observations, bool)
    keep[rows0[2:]] = False
    with pytest.raises(TooFewPointsError, match="image 0"):
        pg.calibration.fit_residual_grids(b.select_observations(keep), spacing=500)
    partial = {k: v for k, v in grids.items() if k != 3}
    with pytest.raises(InputError, match="no residual grid for image"):
        pg.calibration.correct_observations(b, partial)
    with pytest.raises(InputError, match="do not pass fix_exterior"):
        pg.calibration.readjust(b, grids, fix_exterior=False)
    with pytest.raises(InputError, match="Block or a mapping"):
        pg.calibration.correct_observations([1, 2], grids)
    with pytest.raises(InputError, match="roles"):
        pg.calibration.fit_residual_grids(b, roles=("ground",))
    with pytest.raises(InputError, match="overlap"):
        pg.calibration.model_steps(b, overlap=1.5)


def test_readjust_needs_no_datum_of_its_own():
    """Without GNSS, IMU and control points the fixed orientations are the datum."""
    sim = pg.simulate.uav_block(
        "FC300S", seed=5, strips=1, images_per_strip=4, gcps="none", checks=0,
        gnss_sigma=None, imu_sigma_deg=None,
    )  # fmt: skip
    block = sim.truth.with_observations(uv=sim.observed)
    with pytest.raises(pg.errors.DegenerateGeometryError, match="datum"):
        pg.bundle_adjust(block)
    grids = pg.calibration.fit_residual_grids(block, 500, folds=0)
    re = pg.calibration.readjust(block, grids, snooping=False)
    np.testing.assert_allclose(re.block.exterior, block.exterior, rtol=0, atol=1e-12)
    assert re.converged


@pytest.fixture(scope="module")
def ilce_small():
    return pg.simulate.uav_block("ILCE-7RM2", seed=5, strips=2, images_per_strip=4)


def test_visible_field_is_the_whole_field_when_nothing_can_take_it_up(ilce_small):
    """Points, orientations and calibration held: the residuals are the field itself
    (computed minus observed = -field)."""
    sim = ilce_small
    v = pg.calibration.visible_field(sim, hold_points=True, fix_exterior=True, free=())
    tie = sim.truth.role[sim.truth.obs_point] == "tie"
    np.testing.assert_allclose(v[tie], -sim.local[tie], atol=1e-3)


def test_visible_field_of_a_displaced_object_is_nothing(ilce_small):
    """A 'field' that is exactly the image displacement of shifted tie points is taken up
    by the points: nothing of it is visible; with the points held, all of it."""
    import dataclasses

    from photogeom.bundle.residuals import projected_pixels

    sim = ilce_small
    T = sim.truth
    rng = np.random.default_rng(0)
    xyz = T.xyz.copy()
    tie = T.role == "tie"
    xyz[tie] += rng.normal(0.0, 0.05, (int(tie.sum()), 3))  # 5 cm, about one GSD
    field = projected_pixels(T, xyz)[0] - projected_pixels(T)[0]
    fake = dataclasses.replace(sim, local=field)
    rows = tie[T.obs_point]
    v = pg.calibration.visible_field(fake)
    assert np.sqrt(np.mean(v[rows] ** 2)) < 1e-6 * np.sqrt(np.mean(field[rows] ** 2)) + 1e-9
    held = pg.calibration.visible_field(fake, hold_points=True, fix_exterior=True, free=())
    np.testing.assert_allclose(held[rows], -field[rows], atol=1e-3)


def test_check_points_against_surveyed_coordinates(ilce_small):
    """Real blocks: the adjusted block holds its check points triangulated; with their
    surveyed coordinates the errors before and after are the bundle adjustment's and the
    re-adjustment's own check errors (each against the survey, which the adjusted block
    keeps in Block.surveyed)."""
    sim = ilce_small
    fit = pg.bundle_adjust(sim.block, snooping=False)
    grids = pg.calibration.fit_residual_grids(fit.block, 1000, folds=0)
    re = pg.calibration.readjust(fit.block, grids, snooping=False)
    b = sim.block
    check = b.role == "check"
    surveyed = dict(zip(b.point_ids[check].tolist(), b.xyz[check]))
    ev = pg.calibration.evaluate_readjustment(fit, re, surveyed=surveyed)
    assert ev["check_before"]["ids"] == list(fit.check["ids"])
    np.testing.assert_allclose(ev["check_before"]["errors"], fit.check["errors"], atol=1e-9)
    np.testing.assert_allclose(ev["check_after"]["errors"], re.check["errors"], atol=1e-9)
    np.testing.assert_allclose(
        ev["check_before"]["rmse_gsd"], fit.check["rmse"] / fit.block.gsd(), rtol=1e-12
    )
    with pytest.raises(InputError, match="none of the block's check points"):
        pg.calibration.evaluate_readjustment(fit, re, surveyed={"nowhere": (0, 0, 0)})
    with pytest.raises(InputError, match="not both"):
        pg.calibration.evaluate_readjustment(fit, re, sim=sim, surveyed=surveyed)


def test_tie_point_errors_against_the_truth(ilce_small):
    """Every tie point of a block against the truth: the truth itself has none, a block with
    its tie points shifted by a known vector (and its points in another order) has exactly
    that shift, in GSD; untriangulated points are left out."""
    from types import SimpleNamespace

    sim = ilce_small
    T = sim.truth
    same = SimpleNamespace(block=T)
    ev = pg.calibration.evaluate_readjustment(same, same, sim=sim)
    np.testing.assert_allclose(ev["tie_before"]["rmse"], 0.0, atol=1e-12)
    tie = T.role == "tie"
    assert ev["tie_after"]["points"] == int(tie.sum())
    shift = np.array([0.02, -0.04, 0.1])
    xyz = T.xyz.copy()
    xyz[tie] += shift
    xyz[np.flatnonzero(tie)[0]] = np.nan  # one point not triangulated
    order = np.random.default_rng(3).permutation(T.n_points)
    moved = SimpleNamespace(point_ids=T.point_ids[order], xyz=xyz[order], role=T.role[order])
    e = pg.calibration.study._tie_errors(moved, sim)
    assert e["points"] == int(tie.sum()) - 1
    np.testing.assert_allclose(e["rmse"], np.abs(shift), rtol=1e-12)
    np.testing.assert_allclose(e["rmse_gsd"], np.abs(shift) / sim.gsd, rtol=1e-12)


def test_check_points_from_the_survey_the_adjusted_block_keeps(ilce_small):
    """Without sim or surveyed, the check errors come from Block.surveyed: the bundle
    adjustments' own check errors, before and after."""
    fit = pg.bundle_adjust(ilce_small.block, snooping=False)
    grids = pg.calibration.fit_residual_grids(fit.block, 1000, folds=0)
    re = pg.calibration.readjust(fit.block, grids, snooping=False)
    ev = pg.calibration.evaluate_readjustment(fit, re)
    np.testing.assert_allclose(ev["check_before"]["errors"], fit.check["errors"], atol=1e-9)
    np.testing.assert_allclose(ev["check_after"]["errors"], re.check["errors"], atol=1e-9)
    bare = dataclasses.replace(fit, block=fit.block.replace(surveyed=None))
    assert "check_before" not in pg.calibration.evaluate_readjustment(bare, re)


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_grids_from_a_file_correct_the_block(unstable, tmp_path, suffix):
    """The block's integer image ids survive the grids file, so the loaded grids correct
    and re-adjust the block exactly as the fitted ones."""
    _, fit, grids = unstable
    b = fit.block
    assert b.image_ids.dtype.kind == "i"
    back = pg.calibration.load_grids(pg.calibration.save_grids(tmp_path / f"g{suffix}", grids))
    assert list(back) == b.image_ids.tolist()
    want = pg.calibration.correct_observations(b, grids).observations.uv
    got = pg.calibration.correct_observations(b, back).observations.uv
    np.testing.assert_array_equal(got, want)
    if suffix == ".npz":
        re_mem = pg.calibration.readjust(b, grids, snooping=False)
        re_file = pg.calibration.readjust(b, back, snooping=False)
        np.testing.assert_array_equal(re_file.block.xyz, re_mem.block.xyz)
    else:  # a file written before ids kept their type: text ids still match the block
        data = json.loads((tmp_path / "g.json").read_text())
        for entry in data["images"]:
            entry["id"] = str(entry["id"])
        (tmp_path / "old.json").write_text(json.dumps(data))
        old = pg.calibration.load_grids(tmp_path / "old.json")
        assert list(old) == [str(i) for i in b.image_ids.tolist()]
        got = pg.calibration.correct_observations(b, old).observations.uv
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("roles", [("tie", "check"), ("check",), "check", ("control", "check")])
def test_check_points_never_enter_the_grids(unstable, roles):
    _, fit, _ = unstable
    b = fit.block
    assert (b.role == "check").any()  # the block has check points to keep out
    with pytest.raises(InputError, match="check points never enter a residual grid"):
        pg.calibration.fit_residual_grids(b, spacing=500, roles=roles, folds=0)
    # tie and control points may: control residuals are added to the tie residuals
    both = pg.calibration.fit_residual_grids(b, spacing=500, roles=("tie", "control"), folds=0)
    control = b.role[b.obs_point] == "control"
    assert sum(g.sigma_obs.size for g in both.values()) == int(
        ((b.role[b.obs_point] == "tie") | control).sum()
    )


def test_readjust_holds_image_variant_calibration():
    """Per-image f, cx, cy offsets are calibration too: readjust held the group's
    calibration but let the images' offsets move (up to 0.3 px), and the points took the
    change up."""
    sim = pg.simulate.uav_block(
        "ILCE-7RM2",
        seed=1,
        strips=2,
        images_per_strip=4,
        tie_points_per_image=200,
        calibration_variation=(2.0, 1.0, 1.0),
    )
    res = pg.bundle_adjust(sim.block, snooping=False)
    assert res.block.image_variant[res.block.camera_ids[0].item()] == ("f", "cx", "cy")
    grids = pg.calibration.fit_residual_grids(res.block, 500, folds=0)
    re = pg.calibration.readjust(res.block, grids, snooping=False)
    np.testing.assert_array_equal(re.block.calibration_offset, res.block.calibration_offset)
    np.testing.assert_allclose(re.block.exterior, res.block.exterior, atol=1e-12)
    # bundle_adjust(free=()) holds the whole calibration, offsets included
    fixed = pg.bundle_adjust(res.block, free=(), snooping=False)
    np.testing.assert_array_equal(fixed.block.calibration_offset, res.block.calibration_offset)
