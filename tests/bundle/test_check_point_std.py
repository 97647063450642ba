"""Standard deviations of check points: their triangulation's part and the adjusted
cameras' part, scaled by sigma0 a posteriori, against the spread of Monte-Carlo redraws."""

import numpy as np
import pytest

import photogeom as pg


@pytest.fixture(scope="module")
def sim():
    return pg.simulate.uav_block(
        "FC6310", seed=1, strips=2, images_per_strip=4, tie_points_per_image=100, local_field=0.0
    )


def _redraw(sim, rng, image_factor=1.0):
    """The block with every observation redrawn from the truth: image coordinates, GNSS,
    IMU and the control and check points' survey."""
    b, t = sim.block, sim.truth
    known = b.role != "tie"
    uv = sim.ideal + rng.normal(0, 1, sim.ideal.shape) * b.observations.sigma[:, None]
    xyz = b.xyz.copy()
    xyz[known] = t.xyz[known] + rng.normal(0, 1, (int(known.sum()), 3)) * b.point_sigma[known]
    return b.replace(
        xyz=xyz,
        gnss=t.gnss + rng.normal(0, 1, t.gnss.shape) * b.gnss_sigma,
        imu=t.imu + rng.normal(0, 1, t.imu.shape) * b.imu_sigma,
    ).with_observations(uv=sim.ideal + (uv - sim.ideal) * image_factor)


def test_check_point_std_follows_the_monte_carlo_spread(sim):
    """Before: the triangulation's part alone with the a-priori sigma0, the spread 1.35-1.73
    times the reported standard deviations."""
    rng = np.random.default_rng(3)
    chk = np.flatnonzero(sim.block.role == "check")
    xs, ss = [], []
    for _ in range(30):
        f = pg.bundle_adjust(_redraw(sim, rng), snooping=False, point_covariance=True)
        xs.append(f.block.xyz[chk])
        ss.append(f.point_std[chk])
    spread = np.array(xs).std(axis=0, ddof=1)  # (k, 3)
    reported = np.array(ss).mean(axis=0)
    ratio = np.sqrt(np.mean(spread**2, axis=0) / np.mean(reported**2, axis=0))
    assert np.all((ratio > 0.8) & (ratio < 1.2)), ratio


def test_check_point_std_scales_with_sigma0(sim):
    """Image noise twice its a-priori sigma: sigma0 near 2 and the check points' standard
    deviations (dominated by the image observations) larger by about that (before: the
    a-priori sigma0, unchanged)."""
    rng = np.random.default_rng(4)
    chk = np.flatnonzero(sim.block.role == "check")
    block = _redraw(sim, rng)
    one = pg.bundle_adjust(block, snooping=False, point_covariance=True)
    noisy = block.with_observations(uv=sim.ideal + 2.0 * (block.observations.uv - sim.ideal))
    two = pg.bundle_adjust(noisy, snooping=False, point_covariance=True)
    r = two.point_std[chk] / one.point_std[chk]
    s = two.sigma0 / one.sigma0
    assert s > 1.5
    np.testing.assert_allclose(np.median(r, axis=0), s, rtol=0.15)


def test_cameras_part_is_the_difference_to_exact_cameras(sim):
    """Without the cameras' part the covariance is the triangulation with exact cameras
    (photogeom.bundle.triangulate's, times sigma0^2): the cameras' part is positive."""
    from photogeom.bundle.adjustment import Problem
    from photogeom.bundle.options import BundleOptions
    from photogeom.bundle.result import check_point_covariance, statistics_pass

    block = sim.block
    fit = pg.bundle_adjust(block, snooping=False, point_covariance=True)
    chk = np.flatnonzero(block.role == "check")
    tri = pg.bundle.triangulate(fit.block, block.point_ids[chk], covariance=True)
    # the adjusted cameras: the state of the adjusted block, its factor
    adj = Problem(fit.block, BundleOptions())
    state = adj.initial_state()
    weights = np.ones(adj.obs_i.size)
    _, _, F, Q, _, _ = statistics_pass(adj, state, weights, pairs=True, cofactors=False)
    exact = check_point_covariance(adj, state, F, fit.block.xyz[chk], 1.0, cameras=False)
    np.testing.assert_allclose(exact, tri.covariance, rtol=1e-6, atol=1e-12)
    full = check_point_covariance(adj, state, F, fit.block.xyz[chk], 1.0, blocks=Q)
    # the cameras' cofactors from the covariance blocks and from solves with the factor
    solved = check_point_covariance(adj, state, F, fit.block.xyz[chk], 1.0)
    np.testing.assert_allclose(full, solved, rtol=1e-9, atol=1e-15)
    extra = np.linalg.eigvalsh(full - exact)
    assert np.all(extra > -1e-12)
    reported = fit.point_std[chk] ** 2 / fit.sigma0**2
    np.testing.assert_allclose(np.einsum("kii->ki", full), reported, rtol=1e-4)
