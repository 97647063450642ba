"""The bundle adjustment against its peers on the camera model they share with photogeom:
the same minimum as pycolmap's bundle adjuster (Ceres; OPENCV model) and GTSAM's
Levenberg-Marquardt (Cal3DS2), and the same point, exterior-orientation and calibration
covariances as GTSAM's ``Marginals`` on a block with the same weighted datum."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.bundle import read_colmap, reprojection_residuals, write_colmap

sys.path.insert(0, str(Path(__file__).parent))
from peers import (
    CAL3DS2_JACOBIAN,
    CAL3DS2_SET,
    OPENCV_SET,
    block_of,
    free_gauge,
    graph,
    optimize,
    tangent_to_exterior,
    values_of,
)


def _free_block(seed: int = 1, **kw):
    """A 3 x 7 image FC300S block, no control, GNSS or IMU; OpenCV's camera model (no K3;
    B2 only where asked); sigma 1 px, so that the cost is 0.5 sum of squared pixels."""
    sim = pg.simulate.uav_block(
        "FC300S",
        seed=seed,
        gcps="none",
        checks=0,
        gnss_sigma=None,
        imu_sigma_deg=None,
        initial_position_error=1.0,
        initial_attitude_error_deg=0.5,
        local_field=0.0,
        min_rays=3,
        brown={"k3": 0.0, **kw},
    )
    return sim.block.with_observations(sigma=1.0)


def _half_sum_squares(block) -> float:
    r = reprojection_residuals(block, behind="nan")
    assert not np.any(np.isnan(r)), "a point behind a camera"
    return 0.5 * float(np.sum(r**2))


def _assert_same_calibration(ours, other, names):
    g = ours.block.camera_ids[0].item()
    a, b = ours.block.calibrations[0], other.calibrations[0]
    for n in names:
        std = ours.calibration_std[g][n]
        assert abs(getattr(a, n) - getattr(b, n)) <= std / 100, (n, getattr(a, n), getattr(b, n))


def test_same_minimum_as_gtsam():
    """Free network, Cal3DS2 (f, B1, B2, cx, cy, K1, K2, P1, P2 free): GTSAM with a prior on
    the first pose and on one distance (the seven gauge freedoms, met exactly at the
    minimum) reaches photogeom's minimum; GTSAM's own cost function agrees at both."""
    pytest.importorskip("gtsam")
    b = _free_block(b2=0.2)
    ours = pg.bundle_adjust(b, datum="free", free=CAL3DS2_SET, snooping=False)
    assert ours.converged
    g, v = graph(b)
    free_gauge(g, b)
    res = optimize(g, v)
    theirs = block_of(b, res)
    cost_ours, cost_theirs = _half_sum_squares(ours.block), _half_sum_squares(theirs)
    assert cost_ours == pytest.approx(cost_theirs, rel=1e-6)
    assert cost_ours == pytest.approx(0.5 * ours.cost_history[-1], rel=1e-12)
    # GTSAM's graph at GTSAM's solution and at ours (moved into GTSAM's gauge by the priors'
    # own minimum: compare the reprojection factors only)
    n_proj = b.n_observations
    ours_values = values_of(ours.block)
    proj_ours = sum(g.at(k).error(ours_values) for k in range(n_proj))
    proj_theirs = sum(g.at(k).error(res) for k in range(n_proj))
    assert proj_ours == pytest.approx(proj_theirs, rel=1e-6)
    assert proj_ours == pytest.approx(cost_ours, rel=1e-12)
    _assert_same_calibration(ours, theirs, CAL3DS2_SET)


def test_same_minimum_as_pycolmap(tmp_path):
    """Free network, OPENCV (f, B1, cx, cy, K1, K2, P1, P2 free): pycolmap's bundle adjuster
    with refine_principal_point, in its two-camera gauge, reaches photogeom's minimum."""
    pycolmap = pytest.importorskip("pycolmap")
    b = _free_block(b2=0.0)
    ours = pg.bundle_adjust(b, datum="free", free=OPENCV_SET, snooping=False)
    assert ours.converged
    write_colmap(b, tmp_path, model="OPENCV")
    rec = pycolmap.Reconstruction(str(tmp_path))
    opts = pycolmap.BundleAdjustmentOptions()
    opts.print_summary = False
    opts.refine_focal_length = opts.refine_principal_point = opts.refine_extra_params = True
    so = opts.ceres.solver_options
    so.function_tolerance = 1e-12
    so.gradient_tolerance = so.parameter_tolerance = 1e-30
    so.max_num_iterations = 200
    config = pycolmap.BundleAdjustmentConfig()
    for image_id in sorted(rec.reg_image_ids()):
        config.add_image(image_id)
    config.fix_gauge(pycolmap.BundleAdjustmentGauge.TWO_CAMS_FROM_WORLD)
    summary = pycolmap.create_default_bundle_adjuster(opts, config, rec).solve()
    assert summary.is_solution_usable()
    rec.write_text(str(tmp_path))
    theirs = read_colmap(tmp_path, image_key="id")
    cost_ours, cost_theirs = _half_sum_squares(ours.block), _half_sum_squares(theirs)
    assert cost_ours == pytest.approx(cost_theirs, rel=1e-6)
    assert cost_theirs == pytest.approx(summary.ceres_summary.final_cost, rel=1e-6)
    _assert_same_calibration(ours, theirs, OPENCV_SET)


@pytest.fixture(scope="module")
def weighted():
    """A block whose datum both can express exactly: GNSS positions (GPSFactor, the same
    per-axis sigmas), five control points (PriorFactorPoint3, the same sigmas), no IMU;
    image sigmas 0.3 px (tie) and 0.5 px (control). Both adjusted to their minimum."""
    gtsam = pytest.importorskip("gtsam")
    sim = pg.simulate.uav_block(
        "FC300S",
        seed=5,
        checks=0,
        imu_sigma_deg=None,
        initial_attitude_error_deg=0.5,
        local_field=0.0,
        min_rays=3,
        brown={"k3": 0.0},
    )
    b = sim.block
    ours = pg.bundle_adjust(
        b, datum="weighted", free=CAL3DS2_SET, point_covariance=True, snooping=False, ftol=1e-14
    )
    assert ours.converged
    g, v = graph(b, gnss=True, control=True)
    res = optimize(g, v, rtol=1e-14)
    return b, ours, g, res, gtsam.Marginals(g, res)


def test_weighted_minimum_as_gtsam(weighted):
    b, ours, g, res, _ = weighted
    # v'Pv of photogeom is twice GTSAM's error (0.5 sum of whitened squares)
    assert 0.5 * ours.cost_history[-1] == pytest.approx(g.error(res), rel=1e-9)
    assert g.error(values_of(ours.block)) == pytest.approx(g.error(res), rel=1e-9)
    _assert_same_calibration(ours, block_of(b, res), CAL3DS2_SET)


def test_point_covariances_as_gtsams_marginals(weighted):
    """Every tie and control point: photogeom's 3x3 covariance divided by sigma0^2 (its
    cofactor: the a-priori covariance) equals GTSAM's marginal to 1e-6 relative."""
    from gtsam.symbol_shorthand import L

    b, ours, _, _, marg = weighted
    s2 = ours.sigma0**2
    ids = b.point_ids.tolist()
    assert len(ids) > 300 and np.sum(b.role == "control") == 5
    for j, pid in enumerate(ids):
        q = ours.point_covariance(pid) / s2
        ref = marg.marginalCovariance(L(j))
        np.testing.assert_allclose(q, ref, rtol=0, atol=1e-6 * np.abs(ref).max())
    # and the a-posteriori standard deviations are the cofactors scaled by sigma0^2
    np.testing.assert_allclose(
        ours.point_std[0] ** 2, np.diag(marg.marginalCovariance(L(0))) * s2, rtol=1e-6
    )


def test_exterior_and_calibration_covariances_as_gtsams_marginals(weighted):
    """Exterior orientation (X0..kappa; GTSAM's Pose3 tangent, a body-frame rotation and
    translation, converted through the Jacobian of its retraction) and the calibration
    (Cal3DS2's fx = f + B1, fy = f, s = B2, u0, v0, k1, k2, p1 = P2, p2 = P1)."""
    from gtsam.symbol_shorthand import K, X

    b, ours, _, res, marg = weighted
    s2 = ours.sigma0**2
    for i, iid in enumerate(b.image_ids.tolist()):
        J = tangent_to_exterior(res.atPose3(X(i)))
        ref = J @ marg.marginalCovariance(X(i)) @ J.T
        q = ours.image_covariance(iid) / s2
        d = np.sqrt(np.diag(ref))
        np.testing.assert_allclose(q / np.outer(d, d), ref / np.outer(d, d), rtol=0, atol=1e-6)
        # the position block needs no conversion beyond the rotation of the tangent
        R = res.atPose3(X(i)).rotation().matrix()
        ref_pos = R @ marg.marginalCovariance(X(i))[3:, 3:] @ R.T
        np.testing.assert_allclose(q[:3, :3], ref_pos, rtol=0, atol=1e-6 * ref_pos.max())
    names, C = ours.calibration_covariance(b.camera_ids[0].item())
    assert names == ("f", "cx", "cy", "k1", "k2", "p1", "p2", "b1", "b2")
    q = CAL3DS2_JACOBIAN @ (C / s2) @ CAL3DS2_JACOBIAN.T
    ref = marg.marginalCovariance(K(0))
    d = np.sqrt(np.diag(ref))
    np.testing.assert_allclose(q / np.outer(d, d), ref / np.outer(d, d), rtol=0, atol=1e-6)


def test_free_network_covariances_in_the_inner_constraint_datum():
    """Free network: photogeom's point and exterior-orientation covariances are those of the
    inner constraints on the projection centres. Reference: GTSAM's linearisation of the
    same cost at photogeom's solution, a dense normal matrix ``N``, its 7-dimensional null
    space ``G`` found numerically, and the bordered inverse ``[[N, C], [C', 0]]^-1`` with
    ``C`` = G on the centres (GTSAM's translation tangent is R' dC: the constraint
    ``sum G_c' dC = 0`` keeps its form) and zero elsewhere."""
    gtsam = pytest.importorskip("gtsam")
    from gtsam.symbol_shorthand import K, L, X

    b = _free_block(seed=2, b2=0.2).with_observations(sigma=0.5)
    ours = pg.bundle_adjust(
        b, datum="free", free=CAL3DS2_SET, point_covariance=True, snooping=False, ftol=1e-14
    )
    assert ours.converged
    g, _ = graph(b)
    values = values_of(ours.block)
    keys = [X(i) for i in range(b.n_images)] + [L(j) for j in range(b.n_points)] + [K(0)]
    ordering = gtsam.Ordering()
    for k in keys:
        ordering.push_back(k)
    A, _ = g.linearize(values).jacobian(ordering)
    N = A.T @ A
    m, p = b.n_images, b.n_points
    assert N.shape == (6 * m + 3 * p + 9,) * 2
    d = 1.0 / np.sqrt(np.diag(N))
    w, V = np.linalg.eigh(d[:, None] * N * d[None, :])
    assert w[6] < 1e-6 * w[7]  # a seven-dimensional null space
    G = d[:, None] * V[:, :7]
    C = np.zeros_like(G)
    rows = (6 * np.arange(m))[:, None] + np.arange(3, 6)  # translation tangents
    C[rows.ravel()] = G[rows.ravel()]
    n = N.shape[0]
    Q = np.linalg.inv(np.block([[N, C], [C.T, np.zeros((7, 7))]]))[:n, :n]
    s2 = ours.sigma0**2
    for j, pid in enumerate(b.point_ids.tolist()):
        sl = slice(6 * m + 3 * j, 6 * m + 3 * j + 3)
        ref = Q[sl, sl]
        np.testing.assert_allclose(
            ours.point_covariance(pid) / s2, ref, rtol=0, atol=1e-6 * np.abs(ref).max()
        )
    for i, iid in enumerate(b.image_ids.tolist()):
        R = values.atPose3(X(i)).rotation().matrix()
        ref = R @ Q[6 * i + 3 : 6 * i + 6, 6 * i + 3 : 6 * i + 6] @ R.T
        np.testing.assert_allclose(
            ours.image_covariance(iid)[:3, :3] / s2, ref, rtol=0, atol=1e-6 * np.abs(ref).max()
        )
