"""The UAV block simulator: truth consistency, the error budget, structure, options."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.bundle import reprojection_residuals
from photogeom.errors import InputError
from photogeom.simulate import PRESETS, uav_block
from photogeom.simulate.uav import _max_radius

NAMES = ("ILCE-7RM2", "FC6310", "FC300S")


@pytest.fixture(scope="module", params=NAMES)
def sim(request):
    return uav_block(request.param, seed=1, blunders=3)


def test_truth_reprojects_its_ideal_observations_exactly(sim):
    r = reprojection_residuals(sim.truth)
    assert np.abs(r).max() < 1e-9
    np.testing.assert_array_equal(sim.truth.observations.uv, sim.ideal)


def test_observed_is_ideal_plus_field_plus_noise_plus_blunders(sim):
    o = sim.block.observations
    np.testing.assert_allclose(
        sim.observed - sim.ideal, sim.local + sim.noise + sim.blunders, rtol=0, atol=1e-9
    )
    # the field at the ideal pixels, through the public per-image query
    np.testing.assert_allclose(sim.local, sim.local_field(o.image_ids, sim.ideal), atol=1e-12)
    first = o.image_ids == o.image_ids[0]
    np.testing.assert_allclose(
        sim.local[first], sim.local_field(o.image_ids[0], sim.ideal[first]), atol=1e-12
    )
    # blunders: recorded, on tie observations, of the asked size
    assert sim.blunder_rows.size == 3
    assert np.all(sim.block.role[sim.block.obs_point[sim.blunder_rows]] == "tie")
    np.testing.assert_allclose(np.linalg.norm(sim.blunder_offsets, axis=1), 50.0)


def test_projection_against_the_camera_model_and_exterior_orientation(sim):
    """Truth pixels by an independent path: ExteriorOrientation.to_camera and
    MetashapeCalibration.project_camera (one image at a time)."""
    t = sim.truth
    cam = t.calibrations[0]
    for i in (0, t.n_images // 2, t.n_images - 1):
        rows = np.flatnonzero(t.obs_image == i)
        eo = t.images[t.image_ids[i]].exterior
        p = eo.to_camera(t.xyz[t.obs_point[rows]])
        uv = cam.project_camera(np.column_stack([p[:, 0], -p[:, 1], -p[:, 2]]))
        np.testing.assert_allclose(uv, t.observations.uv[rows], rtol=0, atol=1e-8)


def test_structure_is_that_of_a_real_block(sim):
    b, t = sim.block, sim.truth
    b.validate()
    _, per_point = b.observation_counts()
    assert per_point.min() >= 2
    W, H = t.calibrations[0].width, t.calibrations[0].height
    uv = sim.ideal
    assert np.all((uv >= 2.0) & (uv <= np.array([W - 3.0, H - 3.0])))
    _, depth = pg.bundle.projected_pixels(t)
    assert np.all(depth > 0)
    np.testing.assert_array_equal(b.point_ids, t.point_ids)
    np.testing.assert_array_equal(b.image_ids, t.image_ids)
    assert set(b.role) == {"tie", "control", "check"}
    assert sim.control_ids.size == 5 and sim.check_ids.size == 4


def test_every_point_is_observed_by_exactly_the_images_that_see_it(sim):
    """Brute force over all (image, point) pairs: in front, in the frame, and inside the
    domain where the distortion is one-to-one (beyond it the polynomial folds far-away rays
    back into the frame)."""
    t = sim.truth
    m, p = t.n_images, t.n_points
    ii, jj = np.meshgrid(np.arange(m), np.arange(p), indexing="ij")
    ii, jj = ii.ravel(), jj.ravel()
    M = t.rotations()
    d = t.xyz[jj] - t.exterior[ii, :3]
    q = np.einsum("nij,nj->ni", M[ii], d)
    rad = np.hypot(q[:, 0], q[:, 1]) / np.abs(q[:, 2])
    from photogeom.camera.frame_kernel import project_rows

    pr = project_rows(
        t.xyz[jj],
        M[ii],
        t.exterior[ii, :3],
        t.calibration_matrix()[ii],
        t.image_sizes()[ii],
        jacobian=False,
    )
    W, H = t.calibrations[0].width, t.calibrations[0].height
    seen = (
        (pr.depth > 0)
        & (rad <= _max_radius(t.calibrations[0]))
        & np.all(pr.uv >= 2.0, axis=1)
        & (pr.uv[:, 0] <= W - 3.0)
        & (pr.uv[:, 1] <= H - 3.0)
    )
    expected = set(zip(ii[seen].tolist(), jj[seen].tolist()))
    got = set(zip(t.obs_image.tolist(), t.obs_point.tolist()))
    # tie points seen once are dropped with their single observation
    once = np.bincount(jj[seen], minlength=p) < 2
    expected = {(i, j) for i, j in expected if not once[j]}
    assert got == expected


def test_initial_values_come_from_gnss_imu_and_the_nominal_camera(sim):
    b, t = sim.block, sim.truth
    P = sim.preset
    assert b.calibrations[0] == P.nominal_camera()
    assert t.calibrations[0] == P.true_camera()
    np.testing.assert_array_equal(b.exterior[:, :3], b.gnss)
    np.testing.assert_array_equal(b.exterior[:, 3:], b.imu)
    # GNSS noise at the stated sigma, tie points triangulated near the truth
    e = b.gnss - t.exterior[:, :3]
    assert np.all(np.abs(e) < 5 * b.gnss_sigma)
    tie = b.role == "tie"
    err = np.linalg.norm(b.xyz[tie] - t.xyz[tie], axis=1)
    assert np.median(err) < 0.2 * sim.flying_height
    # control and check points at surveyed (noisy) coordinates with their sigmas
    cc = ~tie
    assert np.all(np.abs(b.xyz[cc] - t.xyz[cc]) < 6 * b.point_sigma[cc])


def test_flying_height_from_gsd_and_the_study_presets():
    for name, f_mm, gsd in (
        ("ILCE-7RM2", 35.0, 0.04),
        ("FC6310", 8.8, 0.02),
        ("FC300S", 3.6, 0.025),
    ):
        P = PRESETS[name]
        assert P.focal_length == f_mm and P.gsd == gsd
        assert P.flying_height() == pytest.approx(gsd * f_mm / P.pixel_size)
    s = uav_block("FC6310", seed=3, gsd=0.03, terrain="flat", position_jitter=0.0)
    assert s.flying_height == pytest.approx(0.03 * PRESETS["FC6310"].focal_px)
    # mean depth / true f: the GSD, scaled by nominal / true focal length
    f_true = s.camera.f
    assert s.truth.gsd() == pytest.approx(0.03 * PRESETS["FC6310"].focal_px / f_true, rel=5e-3)
    s2 = uav_block("FC6310", seed=3, flying_height=50.0)
    assert s2.gsd == pytest.approx(50.0 / PRESETS["FC6310"].focal_px)


@pytest.mark.parametrize("name,images", [("ILCE-7RM2", 250), ("FC6310", 195), ("FC300S", 82)])
def test_study_block_sizes(name, images):
    s = uav_block(name, seed=0, size="study", tie_points_per_image=4, local_field=0.0)
    assert s.block.n_images == images == PRESETS[name].study_images


def test_deterministic_by_seed():
    a = uav_block("FC300S", seed=7, blunders=2)
    b = uav_block("FC300S", seed=7, blunders=2)
    c = uav_block("FC300S", seed=8, blunders=2)
    np.testing.assert_array_equal(a.observed, b.observed)
    np.testing.assert_array_equal(a.block.xyz, b.block.xyz)
    np.testing.assert_array_equal(a.block.exterior, b.block.exterior)
    np.testing.assert_array_equal(a.blunder_rows, b.blunder_rows)
    assert a.observed.shape != c.observed.shape or not np.allclose(a.observed, c.observed)


def test_noise_and_field_statistics():
    s = uav_block("ILCE-7RM2", seed=4, tie_points_per_image=300, sigma=0.4, gcp_sigma=0.8)
    tie = s.block.role[s.block.obs_point] == "tie"
    assert np.std(s.noise[tie]) == pytest.approx(0.4, rel=0.05)
    np.testing.assert_array_equal(s.block.observations.sigma[tie], 0.4)
    np.testing.assert_array_equal(s.block.observations.sigma[~tie], 0.8)
    # the strong field of the unstable camera vs the weak one of the stable cameras
    rms = np.sqrt(np.mean(np.sum(s.local**2, axis=1)))
    assert 0.5 < rms < 1.6
    w = uav_block("FC300S", seed=4)
    assert np.sqrt(np.mean(np.sum(w.local**2, axis=1))) < 0.3


def test_local_field_is_smooth_and_varies_slowly_along_the_flight():
    s = uav_block("ILCE-7RM2", seed=5, strips=2, images_per_strip=12, tie_points_per_image=20)
    W, H = 7952, 5304
    g = np.stack(np.meshgrid(np.linspace(0, W - 1, 25), np.linspace(0, H - 1, 17)), -1)
    g = g.reshape(-1, 2)
    F = np.stack([s.local_field(i, g) for i in s.block.image_ids])  # (m, n, 2)
    # smooth: neighbouring grid nodes (330 px apart) differ much less than the field
    step = np.linalg.norm(F[:, 1:] - F[:, :-1], axis=2)
    assert np.median(step) < 0.5 * np.sqrt(np.mean(np.sum(F**2, axis=2)))

    def corr(a, b):
        return np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b))

    m = F.shape[0]
    near = np.mean([corr(F[i], F[i + 1]) for i in range(m - 1)])
    far = np.mean([abs(corr(F[i], F[i + 12])) for i in range(m - 12)])
    assert near > 0.75 and far < near - 0.3
    # an RMS of 0 makes no field
    z = uav_block("FC300S", seed=5, local_field=0.0)
    assert np.all(z.local == 0)


@pytest.mark.parametrize("slope", [1.0, 3.0])
def test_local_field_spectrum_follows_its_slope_and_keeps_its_rms(slope):
    """Fields drawn with ``slope``, sampled over one period of the image and taken apart by
    a 2-D FFT (independent of the simulator's basis): the mean power of the (1, 0) wave over
    that of the (2, 0) wave is 2**(2 slope), and the mean square length over the image is
    the nominal RMS squared (400 independent images; sampling error a few per cent)."""
    from photogeom.simulate.fields import LocalDistortionField

    W, H, n, m = 800.0, 600.0, 32, 400
    F = LocalDistortionField.random(
        np.random.default_rng(3), np.arange(m), W, H, rms=0.7, modes=3, correlation=0.0,
        slope=slope,
    )
    u, v = np.meshgrid(np.arange(n) * W / n, np.arange(n) * H / n, indexing="ij")
    uv = np.column_stack([u.ravel(), v.ravel()])
    d = F.rows(np.repeat(np.arange(m), uv.shape[0]), np.tile(uv, (m, 1)))
    d = d.reshape(m, n, n, 2)
    spec = np.abs(np.fft.fft2(d, axes=(1, 2))) ** 2  # (m, kx, ky, 2)
    p1, p2 = spec[:, 1, 0].mean(), spec[:, 2, 0].mean()
    assert p1 / p2 == pytest.approx(2.0 ** (2 * slope), rel=0.15)
    assert np.sqrt(np.mean(np.sum(d**2, axis=3))) == pytest.approx(0.7, rel=0.05)
    assert F.slope == slope
    s = uav_block("FC300S", seed=2, tie_points_per_image=20, local_field_slope=slope)
    assert s.field.slope == slope and s.options["local_field_slope"] == slope
    np.testing.assert_allclose(
        F.coefficient_std()[:3] / F.coefficient_std()[0],
        np.hypot(F.waves[:3, 0], F.waves[:3, 1]) ** -slope
        / np.hypot(F.waves[0, 0], F.waves[0, 1]) ** -slope,
    )


def test_image_variant_calibration_offsets():
    s = uav_block("FC300S", seed=6, calibration_variation=(3.0, 1.0, 0.0))
    t = s.truth
    assert np.abs(reprojection_residuals(t)).max() < 1e-9
    off = t.calibration_offset
    assert np.all(off[:, 2] == 0) and np.std(off[:, 0]) > 0.5
    assert t.image_variant[s.preset.name] == ("f", "cx")
    assert s.block.image_variant[s.preset.name] == ("f", "cx")
    np.testing.assert_array_equal(s.block.calibration_offset, 0.0)


def test_terrain_options_and_layouts():
    flat = uav_block("FC300S", seed=2, terrain="flat", terrain_height=120.0, gcps="grid3")
    np.testing.assert_allclose(flat.truth.xyz[:, 2], 120.0)
    assert flat.control_ids.size == 9
    assert np.all(flat.truth.exterior[:, 2] > 120.0 + 0.9 * flat.flying_height)

    def ramp(X, Y):
        return 0.05 * np.asarray(X) + 10.0

    r = uav_block("FC300S", seed=2, terrain=ramp, checks="edges", gcps="corners")
    np.testing.assert_allclose(r.truth.xyz[:, 2], ramp(r.truth.xyz[:, 0], 0.0))
    assert r.control_ids.size == 4 and r.check_ids.size == 4
    xy = np.array([[10.0, -20.0], [30.0, -25.0]]) + np.array([500000.0, 4000000.0])
    e = uav_block("FC300S", seed=2, gcps=xy, checks="none", origin=(500000.0, 4000000.0))
    got = e.truth.xyz[np.isin(e.truth.point_ids, e.control_ids), :2]
    np.testing.assert_allclose(got, xy)  # explicit positions are absolute
    assert e.truth.exterior[0, 0] > 499000


def test_without_gnss_and_imu_the_start_is_perturbed_truth():
    s = uav_block("FC300S", seed=3, gnss_sigma=None, imu_sigma_deg=None, initial_position_error=2.0)
    b, t = s.block, s.truth
    assert np.all(np.isnan(b.gnss)) and np.all(np.isnan(b.imu))
    d = b.exterior[:, :3] - t.exterior[:, :3]
    assert 1.0 < np.std(d) < 3.0
    assert 0 < np.degrees(np.std(b.exterior[:, 3:] - t.exterior[:, 3:])) < 4.0


def test_brown_options():
    nb = uav_block("FC300S", seed=1, brown=False)
    c = nb.camera
    assert c.k1 == c.k2 == c.p1 == c.b1 == 0.0 and c.cx == 4.0
    k = uav_block("FC300S", seed=1, brown={"k1": -0.05, "b2": 0.0})
    assert k.camera.k1 == -0.05 and k.camera.b2 == 0.0 and k.camera.k2 == 0.1
    tc = uav_block("FC300S", seed=1, initial_camera="truth")
    assert tc.block.calibrations[0] == tc.truth.calibrations[0]


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(camera="X100"), "unknown camera preset"),
        (dict(forward_overlap=1.0), "forward_overlap"),
        (dict(gcps="star"), "unknown layout"),
        (dict(terrain="rocky"), "terrain must be"),
        (dict(sigma=0.0), "sigma must be > 0"),
        (dict(brown={"k9": 1.0}), "brown: unknown"),
        (dict(size="huge"), "size must be"),
        (dict(local_field_correlation=1.0), r"\[0, 1\)"),
        (dict(local_field_slope=-1.0), "local_field_slope must be >= 0"),
        (dict(blunders=10**7), "blunders"),
        (dict(brown={"k1": -0.6}), "folds over|cannot be inverted"),
    ],
)
def test_bad_options_are_named(kwargs, match):
    kw = dict(seed=0)
    kw.update(kwargs)
    cam = kw.pop("camera", "FC300S")
    with pytest.raises(InputError, match=match):
        uav_block(cam, **kw)


def test_local_field_unknown_image_is_named(sim):
    with pytest.raises(InputError, match="unknown image id"):
        sim.local_field(10**6, [[0.0, 0.0]])
    with pytest.raises(InputError, match=r"unknown image id 'zz' \("):  # not np.str_('zz')
        sim.local_field("zz", [[0.0, 0.0]])


def test_tie_points_do_not_depend_on_the_start_values():
    # which points a block has is a matter of the true geometry: an IMU 20 degrees off (or a
    # start without GNSS/IMU 50 m and 30 degrees off) used to drop the tie points the initial
    # cameras could not intersect (rays crossing behind them): 343 of 370 at seed 0, 50 m, 30 deg
    ref = uav_block("FC300S", seed=1, blunders=20)
    for kw in (
        dict(imu_sigma_deg=20.0),
        dict(gnss_sigma=None, imu_sigma_deg=None, initial_position_error=50.0,
             initial_attitude_error_deg=30.0),
    ):  # fmt: skip
        s = uav_block("FC300S", seed=1, blunders=20, **kw)
        assert s.options["dropped_tie_points"] == 0
        assert s.options["terrain_height_starts"] > 0
        s.block.validate()
        np.testing.assert_array_equal(s.block.point_ids, ref.block.point_ids)
        np.testing.assert_array_equal(s.observed, ref.observed)
        np.testing.assert_array_equal(s.blunder_rows, ref.blunder_rows)
        assert np.all(np.isfinite(s.block.xyz))
        # the points that start on the mean terrain height (0 m) lie on it
        moved = np.flatnonzero(s.block.xyz[:, 2] == 0.0)
        assert moved.size == s.options["terrain_height_starts"]
        np.testing.assert_allclose(
            s.observed - s.ideal, s.local + s.noise + s.blunders, rtol=0, atol=1e-9
        )
        assert np.abs(reprojection_residuals(s.truth)).max() < 1e-9


@settings(max_examples=8, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**31),
    name=st.sampled_from(NAMES),
    terrain=st.sampled_from(["flat", "hilly"]),
    variation=st.booleans(),
    overlap=st.floats(0.55, 0.85),
)
def test_property_truth_is_consistent_and_recovered_by_triangulation(
    seed, name, terrain, variation, overlap
):
    s = uav_block(
        name,
        seed=seed,
        terrain=terrain,
        strips=2,
        images_per_strip=4,
        forward_overlap=overlap,
        tie_points_per_image=25,
        calibration_variation=(2.0, 1.0, 1.0) if variation else None,
    )
    assert np.abs(reprojection_residuals(s.truth)).max() < 1e-9
    np.testing.assert_allclose(
        s.observed - s.ideal, s.local + s.noise + s.blunders, rtol=0, atol=1e-9
    )
    t = pg.bundle.triangulate(s.truth)
    assert t.all_ok, t.describe_failures()
    np.testing.assert_allclose(t.xyz, s.truth.xyz, rtol=0, atol=1e-8 * s.flying_height)
