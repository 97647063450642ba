"""Multi-view triangulation with fixed cameras: noise-free recovery on simulated blocks,
against pg.space_intersection, covariance against Monte Carlo, named failures."""

import numpy as np
import pytest

import photogeom as pg
from photogeom.bundle import Block, triangulate
from photogeom.bundle.triangulate import (
    STATUS_BEHIND,
    STATUS_OK,
    STATUS_POORLY_CONDITIONED,
    STATUS_TOO_FEW_RAYS,
)
from photogeom.errors import InputError
from photogeom.simulate import uav_block


@pytest.mark.parametrize("name", ["ILCE-7RM2", "FC6310", "FC300S"])
def test_noise_free_recovery_on_simulated_blocks(name):
    s = uav_block(name, seed=11, calibration_variation=(2.0, 1.0, 1.0))
    t = triangulate(s.truth, covariance=True)
    assert t.all_ok, t.describe_failures()
    scale = s.flying_height
    np.testing.assert_allclose(t.xyz, s.truth.xyz, rtol=0, atol=1e-8 * scale)
    assert np.all(t.rms < 1e-8)
    assert np.all(np.isfinite(t.covariance)) and np.all(t.std > 0)
    _, per_point = s.truth.observation_counts()
    np.testing.assert_array_equal(t.n_rays, per_point)


def test_agrees_with_space_intersection_on_a_distortion_free_camera():
    """Independent method: pg.space_intersection (per-image loops, image coordinates of the
    InteriorOrientation) minimises the same weighted reprojection error when the camera has
    no distortion, so both give the same points from noisy observations."""
    s = uav_block("FC6310", seed=12, brown=False, local_field=0.0, sigma=0.5)
    b = s.block.replace(exterior=s.truth.exterior).with_calibrations(
        {s.preset.name: s.truth.calibrations[0]}
    )
    pids = s.tie_ids[:6]
    t = triangulate(b, pids)
    io = b.calibrations[0].interior_orientation()
    cams = [(io, b.images[i].exterior) for i in b.image_ids]
    obs = np.full((b.n_images, pids.size, 2), np.nan)
    rows = np.flatnonzero(np.isin(b.observations.point_ids, pids))
    col = np.searchsorted(pids, b.observations.point_ids[rows])
    obs[b.obs_image[rows], col] = io.pixel_to_image(b.observations.uv[rows])
    used = ~np.all(np.isnan(obs[:, :, 0]), axis=1)
    ref = pg.space_intersection(obs[used], [c for c, u in zip(cams, used) if u])
    np.testing.assert_allclose(t.xyz, ref.points, rtol=0, atol=1e-7)
    assert t.covariance is None
    cov = triangulate(b, pids, covariance=True).covariance
    np.testing.assert_allclose(cov, 0.25 * ref.cofactor, rtol=1e-6)


def test_with_distortion_matches_space_intersection_to_a_fraction_of_sigma():
    s = uav_block("FC300S", seed=13, local_field=0.0, sigma=0.3)
    b = s.block.replace(exterior=s.truth.exterior).with_calibrations(
        {s.preset.name: s.truth.calibrations[0]}
    )
    pids = s.tie_ids[:5]
    t = triangulate(b, pids, covariance=True)
    cal = b.calibrations[0]
    io = cal.interior_orientation()
    obs = np.full((b.n_images, pids.size, 2), np.nan)
    rows = np.flatnonzero(np.isin(b.observations.point_ids, pids))
    col = np.searchsorted(pids, b.observations.point_ids[rows])
    obs[b.obs_image[rows], col] = io.pixel_to_image(b.observations.uv[rows])
    used = ~np.all(np.isnan(obs[:, :, 0]), axis=1)
    cams = [(io, b.images[i].exterior) for i, u in zip(b.image_ids, used) if u]
    ref = pg.space_intersection(obs[used], cams)
    # different objectives (distorted pixels vs undistorted image coordinates): close, not equal
    assert np.all(np.abs(t.xyz - ref.points) < 0.1 * t.std)


def test_covariance_against_monte_carlo():
    """400 noisy copies of one point (as 400 points of one block), against the spread."""
    s = uav_block("FC300S", seed=14, local_field=0.0, tie_points_per_image=30)
    t = s.truth
    j = int(np.argmax(t.observation_counts()[1] == 4))
    rows = np.flatnonzero(t.obs_point == j)
    n = 400
    rng = np.random.default_rng(0)
    sigma = 0.5
    uv = np.tile(t.observations.uv[rows], (n, 1)) + rng.normal(0, sigma, (n * rows.size, 2))
    b = Block.from_arrays(
        cameras=t.cameras,
        image_ids=t.image_ids,
        image_camera=[t.camera_ids[0]] * t.n_images,
        exterior=t.exterior,
        point_ids=np.arange(n),
        xyz=np.zeros((n, 3)),
        obs_image_ids=np.tile(t.image_ids[t.obs_image[rows]], n),
        obs_point_ids=np.repeat(np.arange(n), rows.size),
        uv=uv,
        sigma=sigma,
    )
    r = triangulate(b, covariance=True)
    assert r.all_ok
    spread = np.cov(r.xyz.T)
    reported = r.covariance.mean(axis=0)
    np.testing.assert_allclose(np.diag(spread), np.diag(reported), rtol=0.2)
    assert np.all(np.abs(r.xyz.mean(axis=0) - t.xyz[j]) < 4 * np.sqrt(np.diag(reported) / n))


def _pair_block(xyz, centres, angles=None, sigma=0.5, keep=None):
    cal = pg.MetashapeCalibration(4000, 3000, 3000.0)
    m = len(centres)
    ext = np.zeros((m, 6))
    ext[:, :3] = centres
    if angles is not None:
        ext[:, 3:] = angles
    M = pg.opk_matrix(ext[:, 3], ext[:, 4], ext[:, 5]).reshape(-1, 3, 3)
    xyz = np.asarray(xyz, float)
    p = xyz.shape[0]
    ii, jj = np.meshgrid(np.arange(m), np.arange(p), indexing="ij")
    ii, jj = ii.ravel(), jj.ravel()
    q = np.einsum("nij,nj->ni", M[ii], xyz[jj] - ext[ii, :3])
    uv = cal.project_camera(np.column_stack([q[:, 0], -q[:, 1], -q[:, 2]]), behind="nan")
    bad = ~np.all(np.isfinite(uv), axis=1)
    # points behind a camera: mirror image coordinates through the same formula
    uv[bad] = np.column_stack(
        [2000 - 0.5 + 3000 * q[bad, 0] / -q[bad, 2], 1500 - 0.5 + 3000 * q[bad, 1] / q[bad, 2]]
    )
    sel = np.ones(ii.size, bool) if keep is None else keep
    return Block.from_arrays(
        cameras={"c": cal},
        image_ids=np.arange(m),
        image_camera=["c"] * m,
        exterior=ext,
        point_ids=np.arange(p),
        xyz=np.zeros((p, 3)),
        obs_image_ids=ii[sel],
        obs_point_ids=jj[sel],
        uv=uv[sel],
        sigma=sigma,
    )


def test_failures_are_named_per_point():
    C = np.array([[0.0, 0.0, 100.0], [30.0, 0.0, 100.0], [0.0, 0.0, 100.0]])
    pts = np.array([[10.0, 5.0, 0.0], [12.0, -4.0, 3.0], [15.0, 2.0, 400.0], [5.0, 5.0, 0.0]])
    # point 3: only in image 0; point 1: only in images 0 and 2 (same centre: parallel rays)
    keep = np.ones(12, bool)
    keep[[3 + 4 * 1, 3 + 4 * 2]] = False  # point 3 only in image 0
    keep[1 + 4 * 1] = False  # point 1 not in image 1
    b = _pair_block(pts, C, keep=keep)
    t = triangulate(b)
    assert t.status[0] == STATUS_OK
    np.testing.assert_allclose(t.xyz[0], pts[0], atol=1e-8)
    assert t.status[1] == STATUS_POORLY_CONDITIONED
    assert t.status[2] == STATUS_BEHIND  # above the cameras, i.e. behind both
    assert t.status[3] == STATUS_TOO_FEW_RAYS
    assert np.all(np.isnan(t.xyz[1:]))
    msg = t.describe_failures()
    assert "point 1: poorly conditioned" in msg and "point 3: too few rays" in msg
    assert "point 2: behind a camera" in msg


def test_subset_of_images_and_points():
    s = uav_block("FC300S", seed=15, local_field=0.0)
    b = s.truth
    pair = b.image_ids[:2]
    rows = np.isin(b.observations.image_ids, pair)
    both = np.flatnonzero(np.bincount(b.obs_point[rows], minlength=b.n_points) == 2)
    ids = b.point_ids[both[:10]]
    t = triangulate(b, ids, images=pair)
    assert t.all_ok and np.all(t.n_rays == 2)
    np.testing.assert_allclose(t.xyz, b.xyz[both[:10]], atol=1e-8 * s.flying_height)
    np.testing.assert_array_equal(t.point_ids, ids)


def test_bad_input_is_named():
    s = uav_block("FC300S", seed=16, tie_points_per_image=20)
    with pytest.raises(InputError, match="unknown points id"):
        triangulate(s.block, [10**9])
    with pytest.raises(InputError, match="unknown images id"):
        triangulate(s.block, images=[10**9])
    with pytest.raises(InputError, match="min_rays"):
        triangulate(s.block, min_rays=1)


def test_apply_writes_the_points_into_a_block():
    s = uav_block("FC300S", seed=17, tie_points_per_image=30)
    t = triangulate(s.truth, s.tie_ids[:5])
    b = t.apply(s.block)
    rows = np.searchsorted(b.point_ids, s.tie_ids[:5])
    np.testing.assert_allclose(b.xyz[rows], s.truth.xyz[rows], atol=1e-8 * s.flying_height)
    others = np.setdiff1d(np.arange(b.n_points), rows)
    np.testing.assert_array_equal(b.xyz[others], s.block.xyz[others])
    C = np.array([[0.0, 0.0, 100.0], [30.0, 0.0, 100.0]])
    pb = _pair_block([[10.0, 5.0, 0.0], [15.0, 2.0, 400.0]], C)
    bad = triangulate(pb)
    with pytest.raises(InputError, match="point 1: behind a camera"):
        bad.apply(pb)
    kept = bad.apply(pb, on_failure="keep")
    np.testing.assert_array_equal(kept.xyz[1], pb.xyz[1])
