"""Image blocks in hard conditions: bundle adjustment of awkward blocks."""

import math

import numpy as np
import pytest

import photogeom as pg


@pytest.fixture(scope="module")
def small():
    return pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=4).block


def test_camera_group_without_images_is_held_and_named(small):
    """A camera group that no image uses (a spare camera listed in cameras.csv) has no
    observation of its calibration. Before: DegenerateGeometryError '8 unknown(s) have no
    observation (first index 71)' blaming the geometry; now the group is held at its values,
    named in the notes, and the block adjusts as without it."""
    b = small
    g0 = b.camera_ids[0]
    spare = b.replace(
        camera_ids=np.array([*b.camera_ids.tolist(), "spare"], dtype=object),
        calibrations=(*b.calibrations, b.calibrations[0]),
        free={**b.free, "spare": b.free[g0]},
        image_variant={**b.image_variant, "spare": ()},
    )
    fit = pg.bundle_adjust(spare)
    ref = pg.bundle_adjust(b)
    assert fit.converged
    assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-9)
    assert np.allclose(fit.block.exterior, ref.block.exterior, atol=1e-9)
    assert all(math.isnan(v) for v in fit.calibration_std["spare"].values())
    assert fit.block.calibrations[1] == b.calibrations[0]
    assert any("spare" in n and "no images" in n for n in fit.notes)


def test_flat_nadir_block_with_gnss_only_says_the_focal_length_is_undetermined():
    """Flat terrain, nadir images, GNSS positions, no control points: f is separated from
    the terrain height by nothing. std 50 px (2.4 % of f, below the 5 % that alone raised
    the note), f off by 31 px and the check points' heights by 32 GSD, and the only note
    was a count of correlations. Now the note names f, the effect (heights uncertain by
    about 50 GSD) and the fixes; a hilly block with control and GNSS gets none."""
    sim = pg.simulate.uav_block(
        "FC300S", seed=2, terrain="flat", attitude_jitter_deg=0.0, gcps="none"
    )
    res = pg.bundle_adjust(sim.block, snooping=False)
    g = sim.block.camera_ids[0].item()
    std = res.calibration_std[g]["f"]
    assert 20 < std < 0.05 * res.calibration[g]["f"]
    (note,) = [n for n in res.notes if "focal length is poorly determined" in n]
    assert "GSD" in note and "hold f" in note and "oblique" in note
    ok = pg.bundle_adjust(pg.simulate.uav_block("FC300S", seed=2).block, snooping=False)
    assert not any("focal length" in n for n in ok.notes)


def test_correlation_note_names_the_pairs_and_the_fix():
    """The note on high calibration correlations gave only their count ('6 calibration
    correlation(s) above 0.9: those parameters are not separated well by this block'); it
    now names the worst pairs with their correlation and says what to do."""
    sim = pg.simulate.uav_block("FC300S", seed=3, terrain="flat", gcps="none")
    res = pg.bundle_adjust(sim.block, snooping=False)
    assert res.high_correlations
    (note,) = [n for n in res.notes if "calibration correlation(s) above" in n]
    g, n1, n2, rho = max(res.high_correlations, key=lambda h: abs(h[3]))
    assert f"{n1} / {n2} {rho:+.3f} (camera {g})" in note
    assert "hold one of each pair" in note and "oblique images" in note


def test_disconnected_free_network_names_the_parts_by_image(small):
    """Two strips that share no tie point, adjusted as a free network. Before: 'the block
    falls into 2 parts that share no points' without saying which images; now each part is
    listed by its image ids (as the weighted datum's message does)."""
    b = small.without_datum_observations()
    second = np.isin(b.image_ids, b.image_ids[4:])
    in_second = second[b.obs_image]
    seen_first = np.bincount(b.obs_point[~in_second], minlength=b.n_points) > 0
    cut = b.select_observations(~(in_second & seen_first[b.obs_point]))
    cut = cut.drop_weak_points(surveyed=True)
    ids1 = ", ".join(map(str, b.image_ids[:4].tolist()))
    ids2 = ", ".join(map(str, b.image_ids[4:].tolist()))
    with pytest.raises(pg.DegenerateGeometryError, match="2 parts") as info:
        pg.bundle_adjust(cut, datum="free")
    assert f"images {ids1}" in str(info.value) and f"images {ids2}" in str(info.value)


def test_image_with_too_few_observations_is_named_with_the_fix(small):
    """An image with two observations: the error named it but said nothing about what to
    do; it now says to measure more points in it or to delete it."""
    b = small
    rows = np.flatnonzero(b.obs_image == 2)
    keep = np.ones(b.n_observations, dtype=bool)
    keep[rows[2:]] = False
    weak = b.select_observations(keep).drop_weak_points()
    with pytest.raises(pg.InputError, match="cannot be oriented: 2 ") as info:
        pg.bundle_adjust(weak)
    assert "measure more" in str(info.value) and "delete the images" in str(info.value)


def test_local_minimum_from_a_poor_start_is_named():
    """Start 10 m and 5 degrees off on a 100 m flight, tie points intersected from that
    start, calibration free: with the damping starting at 1e-4, Levenberg-Marquardt
    converged (relative cost decrease below ftol) to a local minimum with sigma0 24 (2235
    observations flagged). The points whose own step raised their cost get point-only steps
    since, and both damping starts reach the minimum from the true values (sigma0 1.04), as
    does the remedy the note names (the calibration held first, then freed). The note itself
    stands for any converged sigma0 above 3 times its a-priori value (here: image sigmas a
    quarter of the simulated ones)."""
    sim = pg.simulate.uav_block("FC300S", seed=0, flying_height=100)
    b = sim.block
    rng = np.random.default_rng(100)
    e0 = sim.truth.exterior.copy()
    e0[:, :3] += rng.uniform(-1, 1, (b.n_images, 3)) * 10
    e0[:, 3:] += np.radians(rng.uniform(-1, 1, (b.n_images, 3)) * 5)
    b0 = b.replace(exterior=e0)
    b0 = pg.bundle.triangulate(b0, b.point_ids[b.role == "tie"]).apply(b0, on_failure="keep")
    fit = pg.bundle_adjust(b0, snooping=False, initial_damping=1e-4)
    assert fit.converged and fit.sigma0 < 1.2
    assert not any("local minimum" in n for n in fit.notes)
    held = pg.bundle_adjust(b0, snooping=False, free=(), initial_damping=1e-4)
    again = pg.bundle_adjust(
        held.block, snooping=False, free=b.free[b.camera_ids[0]], initial_damping=1e-4
    )
    assert again.sigma0 < 1.2
    assert fit.sigma0 == pytest.approx(again.sigma0, rel=1e-6)
    default = pg.bundle_adjust(b0, snooping=False)
    assert default.sigma0 == pytest.approx(again.sigma0, rel=1e-6)
    assert not any("local minimum" in n for n in default.notes)
    tight = pg.bundle_adjust(
        b0.with_observations(sigma=0.25 * b0.observations.sigma), snooping=False
    )
    assert tight.converged and tight.sigma0 > 3
    (note,) = [n for n in tight.notes if "local minimum" in n]
    assert "calibration held first" in note


def test_cli_point_behind_camera_names_the_angle_unit_of_the_files(small, cli, tmp_path):
    """A tie point above the cameras at the start of a CSV block (angles in images.csv in
    degrees, omega_deg ...): the command line said 'check the initial exterior orientations
    (angles in radians, ...)', the unit of the library, not of the files it read."""
    xyz = small.xyz.copy()
    j = int(np.flatnonzero(small.role == "tie")[0])
    xyz[j, 2] += 150.0
    pg.bundle.write_csv_block(small.replace(xyz=xyz), tmp_path / "b")
    code, _, err = cli("bundle", "adjust", tmp_path / "b")
    assert code == 2 and "behind the camera" in err
    assert "radians" not in err and "omega_deg" in err
