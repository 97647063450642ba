"""Residual grids estimated inside the bundle adjustment (small simulated blocks)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import GridLayout, adjust_with_grids
from photogeom.calibration.in_adjustment import _datum_rows
from photogeom.errors import InputError

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import node_field, observe


def _rms(v):
    return float(np.sqrt(np.mean(np.sum(v * v, axis=1))))


@pytest.fixture(scope="module")
def small():
    """A small block of the stable FC300S camera (4000 x 3000 px), no local field."""
    return pg.simulate.uav_block(
        "FC300S", seed=3, strips=2, images_per_strip=4, local_field=0.0, sigma=0.2
    )


def _random_nodes(rng, layout, datum, rms):
    """Random node values (ny, nx, 2) without the datum components (px)."""
    z = rng.standard_normal(2 * layout.n_nodes)
    D = _datum_rows(layout, datum)
    z -= D.T @ np.linalg.solve(D @ D.T, D @ z)
    z *= rms / np.sqrt(np.mean(z.reshape(-1, 2) ** 2) * 2)
    return z.reshape(layout.shape[0], layout.shape[1], 2)


def test_noise_free_camera_grid_is_recovered(small):
    """A field shared by the images of the camera, in the grid's function space and without
    its affine part, is recovered with the orientation from noise-free observations."""
    truth = small.truth
    w, h = (int(x) for x in truth.image_sizes()[0])
    L = GridLayout(w, h, 1000.0)
    nodes = _random_nodes(np.random.default_rng(1), L, "affine", 1.0)
    uv = observe(truth, small.ideal, [node_field(L, nodes)] * truth.n_images)
    block = truth.with_observations(uv=uv)
    ga = adjust_with_grids(
        block, 1000.0, per="camera", sigma_constraint=1e3, sigma_amplitude=None, free=(), std=True
    )
    assert ga.converged
    g = ga.grids[truth.image_ids[0]]
    assert g is ga.grids[truth.image_ids[-1]]  # one grid for the camera group
    np.testing.assert_allclose(g.nodes, nodes, atol=2e-4)
    np.testing.assert_allclose(ga.block.exterior[:, :3], truth.exterior[:, :3], atol=1e-4)
    # the corrected observations reproduce the ideal image points
    np.testing.assert_allclose(ga.fit.block.observations.uv, small.ideal, atol=1e-3)
    assert ga.node_std is not None and ga.node_std[truth.camera_ids[0]].shape == (4, 5, 2)


def test_noise_free_image_grids_are_recovered_when_the_object_is_fixed(small):
    """Per-image fields are determined when every point is a control point (the object
    cannot deform to take them up): noise-free recovery of every image's nodes."""
    truth = small.truth
    w, h = (int(x) for x in truth.image_sizes()[0])
    L = GridLayout(w, h, 1000.0)
    rng = np.random.default_rng(2)
    true_nodes = [_random_nodes(rng, L, "similarity", 0.8) for _ in range(truth.n_images)]
    uv = observe(truth, small.ideal, [node_field(L, z) for z in true_nodes])
    block = truth.with_observations(uv=uv).replace(
        role=np.full(truth.n_points, "control", dtype=object),
        point_sigma=np.full((truth.n_points, 3), 1e-5),
    )
    ga = adjust_with_grids(
        block, 1000.0, per="image", sigma_constraint=1e3, sigma_amplitude=None, free=()
    )
    for i, iid in enumerate(truth.image_ids.tolist()):
        g = ga.grids[iid]
        assert g.support.sum() >= 0.6 * g.support.size
        np.testing.assert_allclose(g.nodes[g.support], true_nodes[i][g.support], atol=2e-4)


def test_stiff_grids_give_the_bundle_adjustment(small):
    """With the grids held at zero by their smoothness and datum (tiny sigma_constraint)
    the joint adjustment is the plain bundle adjustment."""
    ref = pg.bundle_adjust(small.block, snooping=False)
    ga = adjust_with_grids(small.block, 1000.0, sigma_constraint=1e-7, std=False)
    assert max(np.abs(g.nodes).max() for g in ga.grids.values()) < 1e-5
    np.testing.assert_allclose(ga.block.exterior[:, :3], ref.block.exterior[:, :3], atol=1e-5)
    np.testing.assert_allclose(ga.block.exterior[:, 3:], ref.block.exterior[:, 3:], atol=1e-8)
    tie = ref.block.role == "tie"
    np.testing.assert_allclose(ga.block.xyz[tie], ref.block.xyz[tie], atol=1e-5)


def test_a_tiny_amplitude_gives_the_bundle_adjustment(small):
    """The amplitude alone (smoothness nearly off) holds every node at zero: the joint
    adjustment is the plain bundle adjustment."""
    ref = pg.bundle_adjust(small.block, snooping=False)
    ga = adjust_with_grids(
        small.block, 1000.0, sigma_constraint=1e3, sigma_amplitude=1e-7, std=False
    )
    assert ga.sigma_amplitude == 1e-7 and ga.to_dict()["sigma_amplitude"] == 1e-7
    assert max(np.abs(g.nodes).max() for g in ga.grids.values()) < 1e-5
    np.testing.assert_allclose(ga.block.exterior[:, :3], ref.block.exterior[:, :3], atol=1e-5)
    np.testing.assert_allclose(ga.block.exterior[:, 3:], ref.block.exterior[:, 3:], atol=1e-8)


def test_sigma0_follows_the_a_priori_sigma0_of_the_options(small):
    """The weights are ``sigma0_prior^2 / sigma^2`` as in the bundle adjustment: with the
    grids held at zero by a tiny amplitude the joint sigma0 is the bundle adjustment's
    (same redundancy, same square sum) for any sigma0_prior, and the standard deviations
    do not change with it. sigma0_prior was ignored: with 2 the bundle adjustment gave
    sigma0 2.02 and the joint adjustment 1.01."""
    kw = dict(sigma_constraint=1e3, sigma_amplitude=1e-7, std=True, max_iterations=30)
    one = adjust_with_grids(small.block, 1000.0, **kw)
    ref = pg.bundle_adjust(small.block, snooping=False, sigma0_prior=2.0)
    ga = adjust_with_grids(small.block, 1000.0, sigma0_prior=2.0, **kw)
    assert ga.redundancy == ref.redundancy == one.redundancy
    assert ga.sigma0 == pytest.approx(ref.sigma0, rel=1e-6)
    assert ga.sigma0 == pytest.approx(2.0 * one.sigma0, rel=1e-9)
    assert ga.fit.sigma0 == pytest.approx(2.0 * one.fit.sigma0, rel=1e-9)
    for iid, g in ga.grids.items():
        assert g.sigma0 == ga.sigma0
        np.testing.assert_allclose(ga.node_std[iid], one.node_std[iid], rtol=1e-9)
        # the grid's own standard deviations: its sigma0 times its cofactors' root
        np.testing.assert_allclose(g.node_std, one.grids[iid].node_std, rtol=1e-9)


def test_temporal_constraints_join_consecutive_images_of_a_camera_interleaved_with_another(
    small,
):
    """Two cameras taking turns (A, B, A, B, ...: a rig's images in the order of
    acquisition): the temporal constraints join the consecutive images of each camera, so
    stiff ones make the grids of a camera equal. Only images next to each other in the
    block were joined: here none, and the grids of a camera differed by 0.3-0.6 px."""
    b = small.block
    gid = b.camera_ids[0]
    two = b.replace(
        camera_ids=np.array(["A", "B"], dtype=object),
        calibrations=(b.calibrations[0],) * 2,
        image_camera=np.arange(b.n_images) % 2,
        free={"A": b.free[gid], "B": b.free[gid]},
        image_variant={"A": (), "B": ()},
    )
    ga = adjust_with_grids(
        two, 1000.0, sigma_temporal=1e-6, sigma_constraint=1.0, sigma_amplitude=0.5, std=False
    )
    nodes = np.array([ga.grids[i].nodes for i in two.image_ids.tolist()])
    for cam in (0, 1):
        np.testing.assert_allclose(nodes[cam::2], nodes[cam : cam + 1].repeat(4, 0), atol=1e-6)
    assert np.abs(nodes[0] - nodes[1]).max() > 0.1  # the two cameras' grids are not joined


def test_the_default_amplitude_follows_smooth_residuals_not_noise(small):
    """At the true parameters the residuals are exactly what the observations were given:
    a smooth field in the grid's function space gives an amplitude of twice its RMS, white
    measurement noise (averaged by the grids' fit) less than half of twice its RMS."""
    truth = small.truth
    w, h = (int(x) for x in truth.image_sizes()[0])
    L = GridLayout(w, h, 1000.0)
    rng = np.random.default_rng(4)
    fields = [node_field(L, _random_nodes(rng, L, "similarity", 0.8)) for _ in truth.image_ids]
    uv = observe(truth, small.ideal, fields)
    tie = truth.role[truth.obs_point] == "tie"
    r = small.ideal - uv  # computed minus observed at the truth: the field at uv
    ga = adjust_with_grids(
        truth.with_observations(uv=uv), 1000.0, per="camera", std=False, max_iterations=1
    )
    rms = float(np.sqrt(np.mean(r[tie] ** 2)))
    assert ga.sigma_amplitude == pytest.approx(2.0 * rms, rel=0.02)
    noisy = truth.with_observations(uv=small.block.observations.uv)  # ideal + 0.2 px noise
    ga = adjust_with_grids(noisy, 1000.0, per="camera", std=False, max_iterations=1)
    noise = float(np.sqrt(np.mean(small.noise[tie] ** 2)))
    assert 0.0 < ga.sigma_amplitude < 0.5 * 2.0 * noise
    no = adjust_with_grids(noisy, 2000.0, per="camera", sigma_amplitude=None, max_iterations=1)
    assert np.isnan(no.sigma_amplitude) and no.to_dict()["sigma_amplitude"] is None


def test_the_amplitude_brings_the_grids_closer_to_the_true_field():
    """The simulated unstable camera: the fields' long waves, which the tie points take up,
    are held near zero instead of left to the datum; the grids differ less from the true
    local field (about 0.76 of its RMS against 1.0 without)."""
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=6)
    fit = pg.bundle_adjust(sim.block, snooping=False)
    kw = dict(sigma_temporal=0.3, sigma_constraint=1.0, std=False)
    ratio = {}
    for sa in ("residuals", None):
        ga = adjust_with_grids(fit.block, 1000.0, sigma_amplitude=sa, **kw)
        ratio[sa] = pg.calibration.field_recovery(sim, ga.grids)["block"]["ratio"]
    assert ratio["residuals"] < 0.9 and ratio["residuals"] < 0.85 * ratio[None]


def test_the_final_fit_keeps_the_joint_points_and_orientation():
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4)
    fit = pg.bundle_adjust(sim.block, snooping=False)
    ga = adjust_with_grids(fit.block, 2000.0, sigma_temporal=0.3, sigma_constraint=1.0)
    assert ga.converged and ga.sigma_temporal == 0.3
    np.testing.assert_allclose(ga.fit.block.exterior, ga.block.exterior, atol=1e-12)
    tie = ga.block.role == "tie"
    np.testing.assert_allclose(ga.fit.block.xyz[tie], ga.block.xyz[tie], atol=1e-6)
    # the grids take up residual: the joint residuals are smaller than the first fit's
    before = _rms(pg.bundle.reprojection_residuals(fit.block))
    assert _rms(ga.fit.residuals[ga.fit.in_adjustment]) < before
    d = ga.to_dict()
    assert d["per"] == "image" and d["grids"] == sim.block.n_images
    g = next(iter(ga.grids.values()))
    assert g.rms_after < g.rms_before


def test_the_small_starting_damping_reaches_the_same_minimum_in_fewer_iterations():
    """The default damping (1e-8 of the diagonal) and the bundle adjustment's 1e-4 end at
    the same minimum, from the simulator's GNSS/IMU start, far from the solution; the
    small one needs fewer iterations (the grids' weak directions are not held back)."""
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4)
    kw = dict(sigma_temporal=0.3, sigma_constraint=1.0, std=False)
    ga = adjust_with_grids(sim.block, 1000.0, **kw)
    ref = adjust_with_grids(sim.block, 1000.0, initial_damping=1e-4, **kw)
    assert ga.converged and ref.converged
    assert ga.iterations < ref.iterations
    assert ga.cost_history[-1] == pytest.approx(ref.cost_history[-1], rel=1e-9)
    for k, g in ga.grids.items():
        np.testing.assert_allclose(g.nodes, ref.grids[k].nodes, atol=1e-4)
    np.testing.assert_allclose(ga.block.exterior[:, :3], ref.block.exterior[:, :3], atol=1e-4)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"spacing": 0}, "positive number of pixels"),
        ({"spacing": True}, "spacing must be a number of pixels, not True"),
        ({"spacing": "1000"}, "spacing must be a number of pixels, not '1000'"),
        ({"spacing": 5000}, "larger than the image"),
        ({"spacing": 1000, "per": "strip"}, "per must be one of"),
        ({"spacing": 1000, "datum": "none"}, "datum must be one of"),
        ({"spacing": 1000, "sigma_constraint": 0}, "sigma_constraint must be a positive"),
        ({"spacing": 1000, "per": "camera", "sigma_temporal": 0.3}, "needs per='image'"),
        ({"spacing": 1000, "loss": "huber"}, "squared loss only"),
        ({"spacing": 1000, "sigma_amplitude": 0}, "sigma_amplitude must be a positive"),
        ({"spacing": 1000, "sigma_amplitude": True}, "sigma_amplitude must be a number of"),
        ({"spacing": 1000, "sigma_temporal": True}, "sigma_temporal must be a number of"),
        ({"spacing": 1000, "sigma_temporal": "0.3"}, "sigma_temporal must be a number of"),
        ({"spacing": 1000, "sigma_amplitude": "vce"}, "'residuals' or None"),
        ({"spacing": 1000, "datum_": "free"}, "free"),
        ({"spacing": 1000, "min_support": -1}, "min_support must be 0 or more"),
        ({"spacing": 1000, "min_support": 2.5}, "min_support must be a whole number"),
        # settings the joint adjustment does not apply (accepted and left out before)
        ({"spacing": 1000, "snooping": True}, "snooping=True is not supported"),
        ({"spacing": 1000, "alpha": 0.01}, "alpha=0.01 is not supported"),
        ({"spacing": 1000, "point_covariance": True}, "point_covariance=True is not supp"),
    ],
)
def test_bad_input_is_named(small, kwargs, match):
    kw = dict(kwargs)
    if "datum_" in kw:
        kw["datum"] = None
        kw["options"] = pg.bundle.BundleOptions(datum=kw.pop("datum_"))
    with pytest.raises(InputError, match=match):
        adjust_with_grids(small.block, **kw)
    with pytest.raises(InputError, match=r"needs a photogeom\.bundle\.Block"):
        adjust_with_grids("block.json", 1000)


def test_an_amplitude_from_zero_residuals_is_named(small):
    with pytest.raises(InputError, match="no tie-point residuals to take it from"):
        adjust_with_grids(small.truth, 1000.0)


def test_node_standard_deviations_match_monte_carlo():
    """The joint covariance of a camera grid against the spread of 40 noisy adjustments
    (weak smoothness and no amplitude, so the pseudo-observations do not act as a prior)."""
    sim = pg.simulate.uav_block(
        "FC300S", seed=5, strips=2, images_per_strip=3, local_field=0.0, sigma=0.3
    )
    truth, sigma = sim.truth, 0.3
    rng = np.random.default_rng(7)
    kw = dict(
        per="camera", sigma_constraint=100.0, sigma_amplitude=None, free=(), max_iterations=20
    )
    est, cof = [], None
    for trial in range(40):
        uv = sim.ideal + rng.normal(0.0, sigma, sim.ideal.shape)
        block = truth.with_observations(uv=uv, sigma=sigma)
        ga = adjust_with_grids(block, 2000.0, std=trial == 0, **kw)
        g = ga.grids[truth.image_ids[0]]
        est.append(g.nodes.copy())
        if trial == 0:
            cof = ga.node_std[truth.camera_ids[0]] / ga.sigma0
    spread = np.std(np.array(est), axis=0, ddof=1)
    ratio = spread / cof  # cof: the standard deviation for sigma0 = 1 (weights 1 / 0.3^2)
    assert 0.8 < float(np.median(ratio)) < 1.2
    assert np.all((ratio > 0.5) & (ratio < 1.6))


def test_compare_in_adjustment_reports_the_three_methods():
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=2, strips=2, images_per_strip=4)
    r = pg.calibration.compare_in_adjustment(sim, 2000.0, combined_spacing=1000.0)
    assert r["images"] == 8 and 0 < r["visible_share"] < 1
    for m in ("post_hoc", "in_adjustment", "combined"):
        assert len(r[m]["check_rmse_gsd"]) == 3 and r[m]["seconds"] > 0
    assert np.isfinite(r["in_adjustment"]["field"]) and np.isnan(r["combined"]["field"])
    # the post-processing of the in-adjustment result takes up more of the residuals
    assert r["combined"]["residual_rms"] < r["in_adjustment"]["residual_rms"]
    assert isinstance(r["in_adjustment_result"], pg.calibration.GridAdjustment)
    # every method also on re-matched observations (the same fresh noise for all)
    for m in ("post_hoc", "in_adjustment", "combined"):
        assert r[m]["mean_step_rematched"] > 0 and len(r[m]["tie_rmse_gsd_rematched"]) == 3
    # the combined run's second grids were fitted to the first observations' noise: on them
    # its step is the lowest, on re-matched ones that advantage is gone
    assert r["combined"]["mean_step"] < r["in_adjustment"]["mean_step"]
    assert r["combined"]["mean_step_rematched"] > r["combined"]["mean_step"]
    off = pg.calibration.compare_in_adjustment(
        sim, 2000.0, combined_spacing=None, rematch_seed=None
    )
    assert "mean_step_rematched" not in off["post_hoc"]
