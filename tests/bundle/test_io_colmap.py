"""COLMAP text models: projections through pycolmap's camera models and poses, round trips,
files written by COLMAP itself, refused models, named errors."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom.bundle import (
    Block,
    bundle_adjust,
    projected_pixels,
    read_colmap,
    reprojection_residuals,
    write_colmap,
)
from photogeom.bundle.io_colmap import COLMAP_MODELS, MODEL_FREE
from photogeom.camera.metashape import MetashapeCalibration
from photogeom.errors import FileFormatError, InputError

sys.path.insert(0, str(Path(__file__).parent))
from colmap_blocks import CALS, H, W, pycolmap_reconstruction
from colmap_blocks import random_block as _block
from colmap_blocks import text_model as _model_dir

pycolmap = pytest.importorskip("pycolmap")


def _pycolmap_pixels(rec, block, image_key="name"):
    """pycolmap's projection of every observation's point (its pose and camera model), in
    photogeom's pixel convention, and its stored 2D points."""
    if image_key == "name":
        by = {im.name: im for im in rec.images.values()}
    else:
        by = {im.image_id: im for im in rec.images.values()}
    o = block.observations
    proj = np.empty((len(o), 2))
    seen = np.empty((len(o), 2))
    order = {}
    for k in range(len(o)):
        im = by[o.image_ids[k].item()]
        X = block.xyz[block.obs_point[k]]
        cam = rec.cameras[im.camera_id]
        proj[k] = cam.img_from_cam(im.cam_from_world() * X) - 0.5
        n = order.get(im.image_id, 0)
        order[im.image_id] = n + 1
        seen[k] = im.points2D[n].xy - 0.5
    return proj, seen


def _assert_same(a: Block, b: Block, tol=1e-12):
    np.testing.assert_array_equal(a.image_ids, b.image_ids)
    np.testing.assert_array_equal(a.point_ids, b.point_ids)
    np.testing.assert_array_equal(a.observations.image_ids, b.observations.image_ids)
    np.testing.assert_array_equal(a.observations.point_ids, b.observations.point_ids)
    np.testing.assert_allclose(a.exterior[:, :3], b.exterior[:, :3], rtol=tol, atol=tol)
    np.testing.assert_allclose(a.rotations(), b.rotations(), atol=tol)
    np.testing.assert_allclose(a.xyz, b.xyz, rtol=tol, atol=0)
    np.testing.assert_allclose(a.observations.uv, b.observations.uv, atol=tol * 1e3)
    np.testing.assert_allclose(a.calibration_matrix(), b.calibration_matrix(), rtol=tol, atol=tol)
    assert [c.width for c in a.calibrations] == [c.width for c in b.calibrations]


@pytest.mark.parametrize("model", list(COLMAP_MODELS))
def test_projection_through_pycolmap(tmp_path, model):
    rng = np.random.default_rng(len(model))
    b = _block(
        rng,
        {7: CALS[model]},
        free={7: MODEL_FREE[model]},
        image_ids=[f"im{i}.jpg" for i in range(5)],
    )
    write_colmap(b, tmp_path)
    first = (tmp_path / "cameras.txt").read_text().splitlines()[3].split()
    assert first[:2] == ["7", model]
    rec = pycolmap.Reconstruction(str(tmp_path))
    assert rec.cameras[7].model.name == model
    proj, seen = _pycolmap_pixels(rec, b)
    uv, _ = projected_pixels(b)
    assert np.abs(proj - uv).max() < 1e-9
    np.testing.assert_allclose(seen, b.observations.uv, atol=1e-12)
    # residuals computed - observed agree with pycolmap's
    np.testing.assert_allclose(reprojection_residuals(b), proj - seen, atol=1e-9)
    # read back: the same block, the model's parameters free (principal point fixed)
    back = read_colmap(tmp_path)
    _assert_same(b, back)
    assert set(back.free[7]) == set(MODEL_FREE[model])
    write_colmap(back, tmp_path / "again")
    assert (tmp_path / "again" / "cameras.txt").read_text() == (
        tmp_path / "cameras.txt"
    ).read_text()


def test_principal_point_free_on_request(tmp_path):
    b = _block(np.random.default_rng(1), {1: CALS["OPENCV"]}, free=MODEL_FREE["OPENCV"])
    write_colmap(b, tmp_path)
    assert set(read_colmap(tmp_path).free[1]) == set(MODEL_FREE["OPENCV"])
    assert {"cx", "cy"} <= set(read_colmap(tmp_path, refine_principal_point=True).free[1])


def test_our_groups_are_written_as_opencv_or_full_opencv(tmp_path):
    """A photogeom group (default free set: f, cx, cy, k1, k2, k3, p1, p2) needs FULL_OPENCV;
    with k3 neither free nor set, OPENCV."""
    rng = np.random.default_rng(2)
    cal = MetashapeCalibration(W, H, 3000.0, cx=3.0, cy=-2.0, k1=-0.03, p1=1e-4)
    b = _block(rng, {"A": cal, "B": CALS["FULL_OPENCV"]})
    b2 = _block(rng, {"A": cal}, free=("f", "cx", "cy", "k1", "k2", "p1", "p2"))
    write_colmap(b, tmp_path / "one")
    write_colmap(b2, tmp_path / "two")
    assert "FULL_OPENCV" in (tmp_path / "one" / "cameras.txt").read_text()
    assert " OPENCV " in (tmp_path / "two" / "cameras.txt").read_text()
    for d, blk in ((tmp_path / "one", b), (tmp_path / "two", b2)):
        rec = pycolmap.Reconstruction(str(d))
        proj, _ = _pycolmap_pixels(rec, blk, image_key="id")
        assert np.abs(proj - projected_pixels(blk)[0]).max() < 1e-9
        back = read_colmap(d, image_key="id")
        np.testing.assert_allclose(back.calibration_matrix(), blk.calibration_matrix(), atol=1e-12)
    # text group ids are numbered 1, 2, ... in block order
    assert list(read_colmap(tmp_path / "one", image_key="id").cameras) == [1, 2]


def test_image_variant_groups_become_one_camera_per_image(tmp_path):
    rng = np.random.default_rng(4)
    b = _block(rng, {0: CALS["RADIAL"]}, free=MODEL_FREE["RADIAL"])
    off = np.zeros((b.n_images, 3))
    off[:, 0] = rng.normal(0, 2, b.n_images)
    off[:, 1:] = rng.normal(0, 1, (b.n_images, 2))
    b = b.replace(calibration_offset=off)
    write_colmap(b, tmp_path)
    rec = pycolmap.Reconstruction(str(tmp_path))
    assert len(rec.cameras) == b.n_images
    proj, _ = _pycolmap_pixels(rec, b, image_key="id")
    assert np.abs(proj - projected_pixels(b)[0]).max() < 1e-9
    back = read_colmap(tmp_path, image_key="id")
    np.testing.assert_allclose(back.calibration_matrix(), b.calibration_matrix(), atol=1e-12)
    np.testing.assert_allclose(reprojection_residuals(back), reprojection_residuals(b), atol=1e-9)


def _variant_block(rng, m=8, p=40):
    """One OPENCV group with image-variant f, cx, cy (offsets of a few px) and a second,
    ordinary group."""
    b = _block(
        rng,
        {0: CALS["OPENCV"], 1: CALS["RADIAL"]},
        m=m,
        p=p,
        free={0: MODEL_FREE["OPENCV"], 1: MODEL_FREE["RADIAL"]},
    )
    off = np.zeros((b.n_images, 3))
    rows = b.image_camera == 0
    off[rows, 0] = rng.normal(0, 2, rows.sum())
    off[rows, 1:] = rng.normal(0, 1, (rows.sum(), 2))
    return b.replace(calibration_offset=off, image_variant={0: ("f", "cx", "cy"), 1: ()})


def test_image_variant_group_is_one_group_again_on_reading(tmp_path):
    """Written as one COLMAP camera per image, read back as the one group with image-variant
    f, cx, cy it was (before: one group per image, each with its own distortion free): the
    adjustment of the read block solves the problem of the written one."""
    b = _variant_block(np.random.default_rng(11))
    write_colmap(b, tmp_path)
    rec = pycolmap.Reconstruction(str(tmp_path))  # COLMAP skips the group's comment line
    assert len(rec.cameras) == 4 + 1
    proj, _ = _pycolmap_pixels(rec, b, image_key="id")
    assert np.abs(proj - projected_pixels(b)[0]).max() < 1e-9
    back = read_colmap(tmp_path, image_key="id")
    assert len(back.calibrations) == 2
    g = back.camera_ids[back.image_camera[0]]
    assert back.image_variant[g] == ("f", "cx", "cy")
    assert back.calibrations[back.image_camera[0]] == b.calibrations[0]  # the group's value
    np.testing.assert_allclose(back.calibration_offset, b.calibration_offset, atol=1e-12)
    np.testing.assert_allclose(back.calibration_matrix(), b.calibration_matrix(), atol=1e-12)
    assert [len(back.free[k]) for k in back.camera_ids.tolist()] == [6, 3]
    fits = [bundle_adjust(x, datum="free") for x in (b, back)]
    assert fits[0].redundancy == fits[1].redundancy  # before: 344, not 351 (4 x 6 vs 5 + 4 x 3)
    assert fits[1].sigma0 == pytest.approx(fits[0].sigma0, rel=1e-9)
    np.testing.assert_allclose(
        fits[1].block.calibration_matrix(), fits[0].block.calibration_matrix(), atol=1e-6
    )
    # written again: the same cameras.txt (ids, values, the group's line)
    write_colmap(back, tmp_path / "again")
    again = (tmp_path / "again" / "cameras.txt").read_text()
    assert again == (tmp_path / "cameras.txt").read_text()


def test_image_variant_names_without_offsets_are_kept(tmp_path):
    rng = np.random.default_rng(12)
    b = _block(rng, {5: CALS["RADIAL"]}, free=MODEL_FREE["RADIAL"])
    b = b.replace(image_variant={5: ("f",)})
    write_colmap(b, tmp_path)
    assert len(pycolmap.Reconstruction(str(tmp_path)).cameras) == 1
    back = read_colmap(tmp_path, image_key="id")
    assert dict(back.image_variant) == {5: ("f",)}  # before: {5: ()}
    _assert_same(b, back)


def test_offsets_without_image_variant_names_are_kept_as_offsets(tmp_path):
    b = _variant_block(np.random.default_rng(15))
    b = b.replace(image_variant={0: (), 1: ()})  # offsets held at their values
    write_colmap(b, tmp_path)
    assert "image_variant none;" in (tmp_path / "cameras.txt").read_text()
    back = read_colmap(tmp_path, image_key="id")
    assert len(back.calibrations) == 2 and not any(back.image_variant.values())
    np.testing.assert_allclose(back.calibration_offset, b.calibration_offset, atol=1e-12)


def test_a_model_colmap_wrote_again_has_one_group_per_camera(tmp_path):
    """COLMAP does not keep the comment: its model is read as COLMAP adjusts it, one group
    per camera with its model's parameters free."""
    b = _variant_block(np.random.default_rng(13))
    write_colmap(b, tmp_path / "ours")
    (tmp_path / "colmap").mkdir()
    pycolmap.Reconstruction(str(tmp_path / "ours")).write_text(str(tmp_path / "colmap"))
    back = read_colmap(tmp_path / "colmap", image_key="id")
    assert len(back.calibrations) == 5 and not any(back.image_variant.values())
    assert all(set(back.free[k]) == set(MODEL_FREE["OPENCV"]) for k in range(1, 5))
    np.testing.assert_allclose(back.calibration_matrix(), b.calibration_matrix(), atol=1e-9)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda t: t.replace("-0.05 0.02", "-0.06 0.02", 1), r"cameras 1 and 2 .* k1 differ"),
        (lambda t: t.replace("CAMERA_ID 1 2 3 4", "CAMERA_ID 1 2 3 4 99"), r"CAMERA_ID 99"),
        (lambda t: t.replace("image_variant f cx cy", "image_variant f k1"), r"f, cx, cy"),
        (lambda t: t.replace("; f 3100.0", "; f=3100.0"), r"must read"),
        (
            lambda t: t.replace("CAMERA_ID 1 2 3 4", "CAMERA_ID 1 2 3 4 5"),
            r"cameras 1 and 5 .* model or image size",
        ),
    ],
)
def test_edited_group_comment_is_refused(tmp_path, edit, match):
    b = _variant_block(np.random.default_rng(14))
    write_colmap(b, tmp_path)
    cams = tmp_path / "cameras.txt"
    text = cams.read_text()
    assert "CAMERA_ID 1 2 3 4\n" in text
    cams.write_text(edit(text))
    with pytest.raises(FileFormatError, match=match) as info:
        read_colmap(tmp_path, image_key="id")
    assert "line 4" in str(info.value)


def test_reads_models_written_by_colmap(tmp_path):
    """pycolmap writes a reconstruction (with its rigs and frames); photogeom reads it and
    projects its points where pycolmap does."""
    rec = pycolmap_reconstruction(pycolmap, np.random.default_rng(5))
    models = list(COLMAP_MODELS)
    rec.write_text(str(tmp_path))
    b = read_colmap(tmp_path)
    assert b.n_images == len(models) and b.n_points == 12 and b.n_observations == 12 * len(models)
    assert [set(b.free[c]) for c in range(1, len(models) + 1)] == [
        set(MODEL_FREE[m]) for m in models
    ]
    back = pycolmap.Reconstruction(str(tmp_path))
    proj, seen = _pycolmap_pixels(back, b)
    assert np.abs(proj - projected_pixels(b)[0]).max() < 1e-9
    np.testing.assert_allclose(seen, b.observations.uv, atol=1e-12)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), key=st.sampled_from(["name", "id"]))
def test_round_trip_random_blocks(tmp_path_factory, seed, key):
    rng = np.random.default_rng(seed)
    model = list(COLMAP_MODELS)[seed % 6]
    text_ids = key == "name"
    b = _block(
        rng,
        {3: CALS[model], 9: CALS["OPENCV"]},
        free={3: MODEL_FREE[model], 9: MODEL_FREE["OPENCV"]},
        image_ids=[f"img_{i:03d}.tif" for i in range(5)] if text_ids else [10, 20, 30, 40, 50],
        point_ids=list(range(100, 120)),
    )
    d = tmp_path_factory.mktemp("colmap")
    write_colmap(b, d)
    back = read_colmap(d, image_key=key)
    _assert_same(b, back)
    assert dict(back.free) == dict(b.free)


# --- refusals and errors ---------------------------------------------------------------------


def test_minimal_model(tmp_path):
    b = read_colmap(_model_dir(tmp_path, "1 SIMPLE_PINHOLE 100 80 90 50 40\n"))
    assert b.n_observations == 2
    np.testing.assert_allclose(b.observations.uv, [[9.5, 19.5], [10.5, 20.5]])
    assert b.cameras[1].cx == 0.0 and b.cameras[1].f == 90.0


@pytest.mark.parametrize(
    ("cameras", "match"),
    [
        (
            "1 OPENCV_FISHEYE 100 80 90 90 50 40 0 0 0 0\n",
            r"line 1: camera 1 has COLMAP model OPENCV_FISHEYE",
        ),
        ("1 FOV 100 80 90 90 50 40 0.1\n", r"model FOV.*supported: SIMPLE_PINHOLE"),
        ("1 FULL_OPENCV 100 80 90 90 50 40 0 0 0 0 0 0.1 0 0\n", r"rational terms k4, k5, k6"),
        ("1 PINHOLE 100 80 90 50 40\n", r"model PINHOLE has 4 parameters.*gives 3"),
        ("# c\n1 PINHOLE 100 80 90 x 50 40\n", r"line 2: a camera parameter is not a number"),
        ("1 SIMPLE_PINHOLE 100 80 -90 50 40\n", r"camera 1: focal length must be > 0"),
    ],
)
def test_refused_cameras(tmp_path, cameras, match):
    with pytest.raises(FileFormatError, match=match):
        read_colmap(_model_dir(tmp_path, cameras))


@pytest.mark.parametrize(
    ("images", "points", "match"),
    [
        (
            None,
            "7 0 0 20 0 0 0 -1 1 0 3 0\n",
            r"points3D.txt, line 1: point 7 is observed in image 3",
        ),
        (None, "7 0 0 20 0 0 0 -1 1 0 2 4\n", r"POINT2D_IDX 4 is out of range for image 2"),
        (None, "7 0 0 20 0 0 0 -1 1 1 2 0\n", r"lists 2D point 1 of image 1.*disagree"),
        (None, "7 0 0 20 0 0 0 -1 1 0\n", r"links 2 2D points to 3D points but .* hold 1"),
        (None, "7 0 0 20 0 0 0 -1 1 0 2 0\n7 0 0 20 0 0 0 -1\n", r"POINT3D_ID 7 appears twice"),
        (
            "1 1 0 0 0 0 0 5 1 a.jpg\n10 20 7 30 40\n2 1 0 0 0 1 0 5 1 b.jpg\n11 21 7\n",
            None,
            r"images.txt, line 2: POINTS2D must be triples",
        ),
        (
            "1 1 0 0 0 0 0 5 1 a.jpg\n10 20 7 30 40 -1\n2 1 0 0 0 1 0 5 2 b.jpg\n11 21 7\n",
            None,
            r"line 3: image 2 refers to camera 2",
        ),
        (
            "1 2 0 0 0 0 0 5 1 a.jpg\n10 20 7 30 40 -1\n2 1 0 0 0 1 0 5 1 b.jpg\n11 21 7\n",
            None,
            r"line 1: the quaternion of image 1 has norm 2",
        ),
        (
            "1 1 0 0 0 0 0 5 1 a.jpg\n10 20 7 30 40 -1\n2 1 0 0 0 1 0 5 1 a.jpg\n11 21 7\n",
            None,
            r"NAME 'a.jpg' appears twice; read with image_key='id'",
        ),
        (
            "1 1 0 0 0 0 0 5 1 a.jpg\n10 20 7\n",
            None,
            r"point 7 is observed in image 2, which is not in",
        ),
        ("# nothing\n", None, r"images\.txt: no images"),
    ],
)
def test_inconsistent_models(tmp_path, images, points, match):
    with pytest.raises(FileFormatError, match=match):
        read_colmap(_model_dir(tmp_path, "1 SIMPLE_PINHOLE 100 80 90 50 40\n", images, points))


def test_missing_files(tmp_path):
    with pytest.raises(FileFormatError, match="not a directory"):
        read_colmap(tmp_path / "none")
    (tmp_path / "cameras.txt").write_text("1 SIMPLE_PINHOLE 100 80 90 50 40\n")
    with pytest.raises(FileFormatError, match=r"images\.txt: no such file"):
        read_colmap(tmp_path)


def test_writer_refusals(tmp_path):
    rng = np.random.default_rng(7)
    for extra in ({"k4": 1e-3}, {"b2": 0.5}):
        cal = MetashapeCalibration(W, H, 3000.0, **extra)
        b = _block(rng, {1: cal})
        name = next(iter(extra)).upper()
        with pytest.raises(InputError, match=rf"camera 1: {name} = .*no COLMAP camera model"):
            write_colmap(b, tmp_path / "x")
    assert not (tmp_path / "x").exists() or not any((tmp_path / "x").iterdir())
    b = _block(rng, {1: CALS["RADIAL"]})
    with pytest.raises(
        InputError, match=r"model SIMPLE_PINHOLE cannot hold k1, k2.*RADIAL|cannot hold"
    ):
        write_colmap(b, tmp_path / "y", model="SIMPLE_PINHOLE")
    write_colmap(b, tmp_path / "y", model="opencv")
    assert "OPENCV" in (tmp_path / "y" / "cameras.txt").read_text()
    ctrl = b.replace(
        role=np.array(["control"] + ["tie"] * (b.n_points - 1)),
        point_sigma=np.full((b.n_points, 3), 0.02),
    )
    with pytest.raises(InputError, match=r"COLMAP text model has no room for 1 control point"):
        write_colmap(ctrl, tmp_path / "z")
    write_colmap(ctrl, tmp_path / "z", drop_extras=True)
    spaced = _block(rng, {1: CALS["RADIAL"]}, image_ids=["a b.jpg", "c", "d", "e", "f"])
    with pytest.raises(InputError, match="white space"):
        write_colmap(spaced, tmp_path / "w")


def test_write_keeps_old_files_when_refused(tmp_path):
    b = _block(np.random.default_rng(8), {1: CALS["RADIAL"]}, free=MODEL_FREE["RADIAL"])
    write_colmap(b, tmp_path)
    before = {p.name: p.read_text() for p in tmp_path.iterdir()}
    bad = b.with_calibrations({1: MetashapeCalibration(W, H, 3000.0, k4=1e-3)})
    with pytest.raises(InputError):
        write_colmap(bad, tmp_path)
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == before


def test_same_minimum_as_colmaps_bundle_adjuster(tmp_path):
    """A BAL block (GTSAM's Balbianello, 5 images, 544 points) adjusted by photogeom reaches
    the minimum COLMAP's bundle adjuster (Ceres) reaches on the model write_colmap wrote: the
    free parameters read from each format are the ones its own tool refines."""
    gtsam = pytest.importorskip("gtsam")
    try:
        src = gtsam.findExampleDataFile("Balbianello.out")
    except Exception:  # pragma: no cover - wheels without data
        pytest.skip("gtsam ships no Balbianello.out")
    gtsam.writeBAL(str(tmp_path / "b.txt"), gtsam.SfmData.FromBundlerFile(src))
    from photogeom.bundle import bundle_adjust, read_bal

    b = read_bal(tmp_path / "b.txt")
    ours = bundle_adjust(b, datum="free", snooping=False)
    assert ours.converged
    write_colmap(b, tmp_path / "model")
    rec = pycolmap.Reconstruction(str(tmp_path / "model"))
    opts = pycolmap.BundleAdjustmentOptions()
    opts.print_summary = False
    so = opts.ceres.solver_options
    so.function_tolerance = so.gradient_tolerance = so.parameter_tolerance = 1e-15
    so.max_num_iterations = 500
    pycolmap.bundle_adjustment(rec, opts)
    rec.write_text(str(tmp_path / "model"))
    theirs = read_colmap(tmp_path / "model", image_key="id")
    cost_ours = 0.5 * np.sum(reprojection_residuals(ours.block) ** 2)
    cost_theirs = 0.5 * np.sum(reprojection_residuals(theirs) ** 2)
    assert cost_ours == pytest.approx(cost_theirs, rel=1e-6)
    assert cost_ours < 0.5 * np.sum(reprojection_residuals(b) ** 2)
    # the calibration does not depend on the datum: the same at the minimum
    np.testing.assert_allclose(
        ours.block.calibration_matrix()[:, [0, 3, 4]],
        theirs.calibration_matrix()[:, [0, 3, 4]],
        rtol=1e-4,
    )


def test_poses_near_gimbal_lock(tmp_path):
    """Images whose phi is 90 deg minus 1e-3 .. 0 (and beyond): COLMAP's quaternions give the
    block's M back to rounding through omega, phi, kappa."""
    rng = np.random.default_rng(12)
    b = _block(rng, {1: CALS["RADIAL"]}, m=6, free=MODEL_FREE["RADIAL"])
    eps = np.array([1e-3, 1e-6, 1e-9, 1e-12, 0.0, -1e-9])
    ext = b.exterior.copy()
    ext[:, 4] = np.pi / 2 - eps
    b = b.replace(exterior=ext)
    write_colmap(b, tmp_path, drop_extras=True)
    back = read_colmap(tmp_path, image_key="id")
    np.testing.assert_allclose(back.rotations(), b.rotations(), rtol=0, atol=2e-15)
    np.testing.assert_allclose(back.exterior[:, :3], b.exterior[:, :3], rtol=1e-14, atol=1e-12)
