"""The specification's "Public API contract": every name, and what the contract says of it.

``test_readme.py`` runs the README's contract block (the names exist and can be called as
written); this file checks what the contract's comments promise, each against something
other than the code under test: the elementary rotation matrices written out, a known
similarity, the simulator's own error budget, the observations themselves.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg

METHODS = ("closed-form", "svd", "quaternion", "dual-quaternion", "gauss-markov", "gauss-helmert")


def _m1(w):
    c, s = np.cos(w), np.sin(w)
    return np.array([[1, 0, 0], [0, c, s], [0, -s, c]])


def _m2(p):
    c, s = np.cos(p), np.sin(p)
    return np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])


def _m3(k):
    c, s = np.cos(k), np.sin(k)
    return np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])


def test_opk_matrix_is_m3_m2_m1_of_radians_and_opk_from_matrix_inverts_it():
    w, p, k = np.radians([10.0, 15.0, 50.0])
    M = pg.opk_matrix(w, p, k)
    assert np.allclose(M, _m3(k) @ _m2(p) @ _m1(w), atol=1e-15)
    assert np.allclose(pg.opk_from_matrix(M), (w, p, k), atol=1e-14)


@pytest.fixture(scope="module")
def similarity():
    """Noise-free pairs of a known similarity, its angles in the transposed convention."""
    rng = np.random.default_rng(7)
    source = rng.uniform(-50.0, 50.0, (12, 3))
    angles = np.radians([25.0, -40.0, 130.0])
    scale, t = 1.7, np.array([500.0, -300.0, 40.0])
    rotation = pg.opk_matrix(*angles).T
    target = scale * source @ rotation.T + t
    return source, target, scale, rotation, t, angles


@pytest.mark.parametrize("method", METHODS)
def test_absolute_orientation_contract(similarity, method):
    source, target, scale, rotation, t, angles = similarity
    fit = pg.absolute_orientation(source, target, method=method)
    # target ~ scale * rotation @ source + translation
    assert fit.scale == pytest.approx(scale, rel=1e-9)
    assert np.allclose(fit.rotation, rotation, atol=1e-9)
    assert np.allclose(fit.translation, t, atol=1e-6)
    # std_errors: keys "tx", "ty", "tz", "scale", "omega", "phi", "kappa"; the angles those
    # with fit.rotation == opk_matrix(omega, phi, kappa).T
    assert set(fit.std_errors) == {"tx", "ty", "tz", "scale", "omega", "phi", "kappa"}
    assert np.allclose([fit.params[a] for a in ("omega", "phi", "kappa")], angles, atol=1e-9)
    assert isinstance(fit.sigma0, float)
    # residuals (n, 3), computed - observed, target system
    assert fit.residuals.shape == source.shape
    assert np.allclose(fit.transform.apply(source), target, atol=1e-6)


def test_absolute_orientation_residuals_are_computed_minus_observed(similarity):
    source, target, *_ = similarity
    moved = target.copy()
    moved[3] += [0.3, -0.2, 0.1]  # the observation moves, the computed value hardly
    for method in METHODS[:-1]:  # Gauss-Helmert: the corrections of the target (its docs)
        fit = pg.absolute_orientation(source, moved, method=method)
        v = fit.residuals
        assert np.allclose(v, fit.transform.apply(source) - moved, atol=1e-9), method
        assert np.dot(v[3], [0.3, -0.2, 0.1]) < 0, method  # observed too large: v < 0


@pytest.fixture(scope="module")
def adjusted():
    sim = pg.simulate.uav_block("FC300S", seed=1)
    return sim, pg.bundle_adjust(sim.block)


def test_block_contract(adjusted):
    sim, res = adjusted
    block = res.block
    assert isinstance(sim.block, pg.bundle.Block) and isinstance(sim.truth, pg.bundle.Block)
    assert isinstance(block, pg.bundle.Block)
    assert res.converged and res.iterations >= 1 and res.redundancy > 0
    assert 0.5 < res.sigma0 < 2.0  # the simulated noise entered with its own sigmas
    for image_id in block.image_ids:
        img = block.images[image_id]
        assert isinstance(img.exterior, pg.ExteriorOrientation)
        assert isinstance(block.cameras[img.camera], pg.MetashapeCalibration)
    roles = {block.points[pid].role for pid in block.point_ids}
    assert roles == {"tie", "control", "check"}
    assert block.points[block.point_ids[0]].xyz.shape == (3,)
    obs = block.observations
    n = len(obs.image_ids)
    assert obs.point_ids.shape == (n,) and obs.uv.shape == (n, 2) and obs.sigma.shape == (n,)


def test_reprojection_residuals_are_computed_minus_observed_in_observation_order(adjusted):
    sim, _ = adjusted
    # the truth reprojects onto the ideal pixels; against the noisy observations, row for
    # row, its residuals are minus what the simulator added to each observation
    truth = sim.truth.with_observations(uv=sim.block.observations.uv)
    v = pg.bundle.reprojection_residuals(truth)
    assert v.shape == sim.block.observations.uv.shape
    assert np.allclose(v, -(sim.local + sim.noise + sim.blunders), atol=1e-6)


def test_bal_and_colmap_round_trips_keep_the_projection(adjusted, tmp_path):
    sim, res = adjusted
    v = pg.bundle.reprojection_residuals(res.block)
    pg.bundle.write_colmap(res.block, tmp_path / "model", drop_extras=True)
    model = pg.bundle.read_colmap(tmp_path / "model")
    assert np.allclose(pg.bundle.reprojection_residuals(model), v, atol=1e-6)
    # BAL holds f, k1, k2 per image: a block on that model (the simulator's start)
    pg.bundle.write_bal(sim.block, tmp_path / "b.bal", drop_extras=True)
    bal = pg.bundle.read_bal(tmp_path / "b.bal")
    v0 = pg.bundle.reprojection_residuals(sim.block)
    assert np.allclose(pg.bundle.reprojection_residuals(bal), v0, atol=1e-6)


@pytest.fixture(scope="module")
def unstable():
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4)
    return sim, pg.bundle_adjust(sim.block)


def test_local_field_is_what_the_simulator_added(unstable):
    sim, _ = unstable
    obs = sim.block.observations
    for image_id in obs.image_ids[:1]:
        rows = obs.image_ids == image_id
        # observed = ideal + field (+ noise): the field is evaluated at the ideal pixel
        assert np.allclose(sim.local_field(image_id, sim.ideal[rows]), sim.local[rows])


def test_residual_grid_contract(unstable):
    sim, res = unstable
    block = res.block
    grids = pg.calibration.fit_residual_grids(block, spacing=500)
    assert set(grids) == set(block.image_ids)
    v = pg.bundle.reprojection_residuals(block)
    obs = block.observations
    image_id = block.image_ids[0]
    rows = obs.image_ids == image_id
    modelled = grids[image_id].evaluate(obs.uv[rows])
    assert modelled.shape == (rows.sum(), 2)
    # the modelled residual, computed - observed: it follows the residuals it was fitted
    # to, and so points against the true field the observations carry
    assert np.corrcoef(modelled.ravel(), v[rows].ravel())[0, 1] > 0.5
    assert (
        np.corrcoef(modelled.ravel(), sim.local_field(image_id, obs.uv[rows]).ravel())[0, 1] < -0.3
    )
    block2 = pg.calibration.correct_observations(block, grids)
    assert np.allclose(block2.observations.uv[rows], obs.uv[rows] + modelled)
    res2 = pg.calibration.readjust(block, grids)  # EO and Brown fixed
    for image_id in block.image_ids:
        a, b = block.images[image_id].exterior, res2.block.images[image_id].exterior
        assert np.allclose([a.X0, a.Y0, a.Z0], [b.X0, b.Y0, b.Z0], atol=1e-9)
    steps = pg.calibration.model_steps(block)
    order = list(block.image_ids)
    for a, b in steps:  # stereo models of about 60 % overlap: at 70 %, neighbouring images
        assert order.index(b) - order.index(a) == 1
    assert all(np.isfinite(s) and s >= 0 for s in steps.values())


def test_relative_orientation_contract():
    io = pg.InteriorOrientation(152.14, unit="mm")
    ground = np.array(
        [[1000, 800, 100], [1300, 650, 169], [1250, 950, 140], [950, 600, 120],
         [1150, 700, 180], [1050, 1000, 110.0], [1200, 820, 150]]
    )  # fmt: skip
    eo1 = pg.ExteriorOrientation(1114.0, 862.0, 1600.0, *np.radians([2.0, 3.0, 10.0]))
    eo2 = pg.ExteriorOrientation(1500.0, 880.0, 1610.0, *np.radians([-1.0, 2.0, 8.0]))
    xy1, xy2 = pg.project(ground, io, eo1), pg.project(ground, io, eo2)
    ro = pg.relative_orientation(xy1, xy2, io, io, method="dependent", sigma=0.005)
    e1, e2 = ro.exterior1, ro.exterior2
    # dependent: image 1 at the origin with M = I, base component bx = 1
    assert (e1.X0, e1.Y0, e1.Z0, e1.omega, e1.phi, e1.kappa) == (0, 0, 0, 0, 0, 0)
    assert e2.X0 == 1.0
    assert set(ro.std_errors) == {"by", "bz", "omega2", "phi2", "kappa2"}
    assert ro.parallax.shape == (len(ground),)
    assert np.max(np.abs(ro.parallax)) < 1e-9  # exact observations: no y-parallax
    # the model is the ground up to a similarity: the relative rotation is the true one
    true = (
        pg.opk_matrix(eo2.omega, eo2.phi, eo2.kappa)
        @ pg.opk_matrix(eo1.omega, eo1.phi, eo1.kappa).T
    )
    assert np.allclose(pg.opk_matrix(e2.omega, e2.phi, e2.kappa), true, atol=1e-9)
