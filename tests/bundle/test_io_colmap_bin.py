"""COLMAP binary models: models pycolmap writes read to the last bit as their text twins,
photogeom's binary files read by pycolmap, the layout against an encoder written from
COLMAP's documentation, round trips, named errors for damaged files."""

from __future__ import annotations

import shutil
import struct
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from photogeom.bundle import (
    Block,
    projected_pixels,
    read_block,
    read_colmap,
    write_block,
    write_colmap,
)
from photogeom.bundle.io_colmap import COLMAP_MODELS, MODEL_FREE
from photogeom.errors import FileFormatError, InputError, OutputError

sys.path.insert(0, str(Path(__file__).parent))
from colmap_binary import text_to_binary
from colmap_blocks import CALS, pycolmap_reconstruction, text_model
from colmap_blocks import random_block as _block

pycolmap = pytest.importorskip("pycolmap")

def _all_models_block(seed=3, **kw) -> Block:
    rng = np.random.default_rng(seed)
    cams = {10 + k: CALS[m] for k, m in enumerate(COLMAP_MODELS)}
    free = {10 + k: MODEL_FREE[m] for k, m in enumerate(COLMAP_MODELS)}
    return _block(rng, cams, m=8, p=30, free=free, **kw)


def _assert_identical(a: Block, b: Block):
    """Every array of the two blocks equal to the last bit."""
    for name in ("image_ids", "point_ids", "camera_ids", "image_camera", "exterior", "xyz",
                 "calibration_offset"):  # fmt: skip
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and np.array_equal(x, y), name
    oa, ob = a.observations, b.observations
    for name in ("image_ids", "point_ids", "uv"):
        assert np.array_equal(getattr(oa, name), getattr(ob, name)), name
    assert np.array_equal(a.obs_image, b.obs_image) and np.array_equal(a.obs_point, b.obs_point)
    assert np.array_equal(a.calibration_matrix(), b.calibration_matrix())
    assert a.calibrations == b.calibrations
    assert dict(a.free) == dict(b.free) and dict(a.image_variant) == dict(b.image_variant)
    ca, cb = a.colmap_images, b.colmap_images
    for name in ("keys", "image_id", "name"):
        assert np.array_equal(getattr(ca, name), getattr(cb, name)), name
    assert np.array_equal(a.observations.sigma, b.observations.sigma)


# --- the peer: pycolmap writes both models, photogeom reads the same numbers ----------------


@pytest.mark.parametrize(
    "options",
    [
        {"image_key": "id"},
        {"image_key": "name", "refine_principal_point": True, "sigma": 0.7},
    ],
)
def test_pycolmap_binary_model_reads_as_its_text_model_to_the_last_bit(tmp_path, options):
    rec = pycolmap_reconstruction(pycolmap, np.random.default_rng(11), unlinked=True)
    text, binary = tmp_path / "text", tmp_path / "binary"
    text.mkdir()
    binary.mkdir()
    rec.write_text(str(text))
    rec.write_binary(str(binary))
    assert (binary / "rigs.bin").is_file() and (binary / "frames.bin").is_file()
    a, b = read_colmap(text, **options), read_colmap(binary, **options)
    _assert_identical(a, b)
    assert b.n_images == 6 and b.n_points == 12 and b.n_observations == 72
    # and the numbers are pycolmap's own: 2D points, 3D points, poses
    by_id = {int(i): k for k, i in enumerate(b.colmap_images.image_id)}
    o = b.observations
    for iid, im in rec.images.items():
        rows = np.flatnonzero(b.obs_image == by_id[iid])
        xy = np.array([p.xy for p in im.points2D if p.has_point3D()])
        assert np.array_equal(o.uv[rows] + 0.5, xy)
        q = im.cam_from_world().rotation.quat  # x, y, z, w
        R = np.diag([1.0, -1.0, -1.0]) @ Rotation.from_quat(q).as_matrix()
        np.testing.assert_allclose(b.rotations()[by_id[iid]], R, atol=2e-16 * 8)
    xyz = np.array([rec.points3D[int(p)].xyz for p in b.point_ids])
    assert np.array_equal(b.xyz, xyz)


def test_binary_model_of_colmap_is_read_like_read_block_and_cli(tmp_path, cli):
    rec = pycolmap_reconstruction(pycolmap, np.random.default_rng(2), unlinked=True)
    rec.write_binary(str(tmp_path))
    ref = read_colmap(tmp_path)
    _assert_identical(read_block(tmp_path), ref)
    _assert_identical(read_block(tmp_path, "colmap-bin"), ref)
    code, out, err = cli("bundle", "convert", tmp_path, tmp_path / "csv", "--to", "csv")
    assert code == 0, err
    assert "(colmap-bin)" in out
    back = read_block(tmp_path / "csv")
    np.testing.assert_array_equal(back.observations.uv, ref.observations.uv)


# --- photogeom writes: pycolmap reads the binary files as the text files ---------------------


def test_written_binary_model_is_read_by_pycolmap_as_the_text_model(tmp_path):
    b = _all_models_block()
    write_colmap(b, tmp_path / "text")
    write_colmap(b, tmp_path / "binary", binary=True)
    rt = pycolmap.Reconstruction(str(tmp_path / "text"))
    rb = pycolmap.Reconstruction(str(tmp_path / "binary"))
    assert rb.num_rigs() == rt.num_rigs() == 6 and rb.num_frames() == 8
    assert sorted(rb.cameras) == sorted(rt.cameras)
    for cid, cam in rt.cameras.items():
        other = rb.cameras[cid]
        assert other.model == cam.model and (other.width, other.height) == (cam.width, cam.height)
        assert np.array_equal(other.params, cam.params)
    assert sorted(rb.images) == sorted(rt.images)
    for iid, im in rt.images.items():
        other = rb.images[iid]
        assert (other.name, other.camera_id) == (im.name, im.camera_id)
        pa, pb = other.cam_from_world(), im.cam_from_world()
        assert np.array_equal(pa.rotation.quat, pb.rotation.quat)
        assert np.array_equal(pa.translation, pb.translation)
        assert [(p.xy.tolist(), p.point3D_id) for p in other.points2D] == [
            (p.xy.tolist(), p.point3D_id) for p in im.points2D
        ]
    assert sorted(rb.points3D) == sorted(rt.points3D)
    for pid, pt in rt.points3D.items():
        other = rb.points3D[pid]
        assert np.array_equal(other.xyz, pt.xyz)
        assert sorted((e.image_id, e.point2D_idx) for e in other.track.elements) == sorted(
            (e.image_id, e.point2D_idx) for e in pt.track.elements
        )


def test_written_files_are_colmaps_documented_layout(tmp_path):
    """The binary writer gives byte for byte what an encoder written from COLMAP's layout
    (tests/bundle/colmap_binary.py, struct record by record) makes of the text model."""
    b = _all_models_block()
    write_colmap(b, tmp_path / "text")
    write_colmap(b, tmp_path / "binary", binary=True)
    text_to_binary(tmp_path / "text", tmp_path / "encoded")
    for name in ("cameras.bin", "images.bin", "points3D.bin"):
        assert (tmp_path / "binary" / name).read_bytes() == (
            tmp_path / "encoded" / name
        ).read_bytes(), name


@settings(max_examples=20, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    key=st.sampled_from(["name", "id"]),
    shuffled=st.booleans(),
)
def test_round_trip_random_blocks(tmp_path_factory, seed, key, shuffled):
    rng = np.random.default_rng(seed)
    model = list(COLMAP_MODELS)[seed % 6]
    pid = list(range(100, 100 + 4 * 20, 4))
    if shuffled:  # written in ascending id order: read back in that order
        rng.shuffle(pid)
    b = _block(
        rng,
        {3: CALS[model], 9: CALS["OPENCV"]},
        free={3: MODEL_FREE[model], 9: MODEL_FREE["OPENCV"]},
        image_ids=[f"img {i:03d}.tif" for i in range(5)] if key == "name" else [10, 2, 30, 4, 7],
        point_ids=pid,
        m=5,
        p=20,
    )
    d = tmp_path_factory.mktemp("colmap")
    write_colmap(b, d / "bin", binary=True)
    back = read_colmap(d / "bin", image_key=key)
    if key == "id":  # a text model of the same block reads as the same block
        write_colmap(b, d / "txt")
        text = read_colmap(d / "txt", image_key=key)
        order = np.argsort(text.point_ids, kind="stable")
        assert np.array_equal(back.point_ids, text.point_ids[order])
        assert np.array_equal(back.xyz, text.xyz[order])
        assert np.array_equal(back.observations.uv, text.observations.uv)
        assert back.calibrations == text.calibrations and dict(back.free) == dict(text.free)
        assert np.array_equal(back.exterior, text.exterior)
    # against the block itself: ids, observations, projections
    assert np.array_equal(np.sort(back.point_ids), np.sort(b.point_ids))
    assert sorted(back.image_ids.tolist()) == sorted(b.image_ids.tolist())
    pb, _ = projected_pixels(b)
    pk, _ = projected_pixels(back)
    ob, ok = b.observations, back.observations
    key_b = {(str(i), int(p)): k for k, (i, p) in enumerate(zip(ob.image_ids, ob.point_ids))}
    rows = [key_b[(str(i), int(p))] for i, p in zip(ok.image_ids, ok.point_ids)]
    assert np.array_equal(back.observations.uv, b.observations.uv[rows] + 0.5 - 0.5)
    np.testing.assert_allclose(pk, pb[rows], atol=1e-9)


def test_options_of_the_writer_and_write_block(tmp_path):
    b = _all_models_block()
    write_block(b, tmp_path / "a", "colmap-bin")
    write_block(b, tmp_path / "b", "colmap", binary=True)
    write_block(b, tmp_path / "a")  # an existing binary model stays binary
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == sorted(
        p.name for p in (tmp_path / "b").iterdir()
    ) == ["cameras.bin", "frames.bin", "images.bin", "points3D.bin", "rigs.bin"]
    for name in ("cameras.bin", "images.bin", "points3D.bin"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    # the model option: PINHOLE for a SIMPLE_PINHOLE camera
    write_colmap(b, tmp_path / "c", binary=True, model={10: "PINHOLE"})
    assert pycolmap.Reconstruction(str(tmp_path / "c")).cameras[10].model_name == "PINHOLE"


def test_image_variant_group_is_refused_without_drop_extras(tmp_path):
    rng = np.random.default_rng(4)
    b = _block(rng, {1: CALS["OPENCV"]}, free={1: MODEL_FREE["OPENCV"]})
    off = np.zeros((b.n_images, 3))
    off[:, 0] = np.arange(b.n_images) * 1.5
    b = b.replace(calibration_offset=off, image_variant={1: ("f",)})
    with pytest.raises(InputError, match=r"camera group 1 has image-variant .*drop_extras=True"):
        write_colmap(b, tmp_path / "x", binary=True)
    assert not (tmp_path / "x").exists()
    write_colmap(b, tmp_path / "x", binary=True, drop_extras=True)
    back = read_colmap(tmp_path / "x", image_key="id")
    assert len(back.calibrations) == b.n_images  # one camera per image, as COLMAP adjusts
    np.testing.assert_allclose(projected_pixels(back)[0], projected_pixels(b)[0], atol=1e-9)


def test_names_the_binary_model_cannot_hold_are_refused(tmp_path):
    b = _block(np.random.default_rng(1), {1: CALS["PINHOLE"]}, image_ids=["a", "b\0x", "c",
                                                                         "d", "e"])  # fmt: skip
    with pytest.raises(InputError, match=r"'b\\x00x'.*NUL"):
        write_colmap(b, tmp_path, binary=True)


def test_a_folder_holds_one_model(tmp_path):
    b = _all_models_block()
    write_colmap(b, tmp_path / "t")
    with pytest.raises(OutputError, match=r"binary model into .* holds a COLMAP text model"):
        write_colmap(b, tmp_path / "t", binary=True)
    write_colmap(b, tmp_path / "b", binary=True)
    with pytest.raises(OutputError, match=r"text model into .* holds a COLMAP binary model"):
        write_colmap(b, tmp_path / "b")
    both = tmp_path / "both"
    shutil.copytree(tmp_path / "t", both)
    for f in (tmp_path / "b").iterdir():
        shutil.copy(f, both / f.name)
    # the same model both ways (a binary model converted to text in place): read
    _assert_identical(read_colmap(both), read_colmap(tmp_path / "b"))
    _assert_identical(read_block(both), read_colmap(tmp_path / "b"))
    lines = (both / "points3D.txt").read_text().splitlines()
    row = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    f = lines[row].split()
    f[1] = repr(float(f[1]) + 0.001)  # one point 1 mm off in the text model
    lines[row] = " ".join(f)
    (both / "points3D.txt").write_text("\n".join(lines) + "\n")
    msg = r"holds both .* they differ \(their point coordinates first\)"
    with pytest.raises(FileFormatError, match=msg + r".*binary=True .* binary=False"):
        read_colmap(both)
    with pytest.raises(FileFormatError, match=msg + r".*kind='colmap-bin' .* kind='colmap'"):
        read_block(both)
    _assert_identical(read_colmap(both, binary=True), read_colmap(tmp_path / "b"))
    text, first = read_colmap(both, binary=False), read_colmap(tmp_path / "t")
    assert np.abs(text.xyz - first.xyz).max() == pytest.approx(0.001)  # the text as it is
    with pytest.raises(FileFormatError, match=r"holds a COLMAP binary model .*pass binary=True"):
        read_colmap(tmp_path / "b", binary=False)
    with pytest.raises(FileFormatError, match=r"holds a COLMAP text model .*pass binary=False"):
        read_colmap(tmp_path / "t", binary=True)


def test_cli_formats(tmp_path, cli):
    b = _all_models_block()
    write_colmap(b, tmp_path / "t")
    code, _, err = cli("bundle", "convert", tmp_path / "t", tmp_path / "b", "--to", "colmap-bin")
    assert code == 0, err
    code, _, err = cli("bundle", "convert", tmp_path / "t", tmp_path / "t2", "--to", "colmap")
    assert code == 0, err  # the same conversion (through the block's angles) as text
    _assert_identical(read_colmap(tmp_path / "b"), read_colmap(tmp_path / "t2"))
    code, _, err = cli("bundle", "convert", tmp_path / "b", tmp_path / "o", "--from", "colmap")
    assert code == 2 and "holds a COLMAP binary model" in err and "--from colmap-bin" in err
    for f in (tmp_path / "t").iterdir():
        shutil.copy(f, tmp_path / "b" / f.name)
    code, _, err = cli("bundle", "convert", tmp_path / "b", tmp_path / "o", "--to", "csv")
    assert code == 2 and "--from colmap-bin for the .bin files or --from colmap" in err
    code, _, err = cli("bundle", "convert", tmp_path / "b", tmp_path / "o", "--to", "csv",
                       "--from", "colmap-bin")  # fmt: skip
    assert code == 0, err


def test_cli_adjust_writes_the_binary_model_it_read(tmp_path, cli):
    b = _block(np.random.default_rng(8), {1: CALS["SIMPLE_RADIAL"]}, m=6, p=40,
               free={1: ("f",)})  # fmt: skip
    write_colmap(b, tmp_path / "in", binary=True)
    code, _, err = cli("bundle", "adjust", tmp_path / "in", "--datum", "free", "-o",
                       tmp_path / "out", "--json")  # fmt: skip
    assert code == 0, err
    assert (tmp_path / "out" / "images.bin").is_file()
    assert not (tmp_path / "out" / "images.txt").exists()
    assert pycolmap.Reconstruction(str(tmp_path / "out")).num_points3D() == 40


# --- damaged files: named errors, never anything else ----------------------------------------


def _text_model(tmp_path, cameras, images=None, points=None):
    """A text model in ``tmp_path / "text"`` and its binary model (the encoder's) in
    ``tmp_path / "bin"``."""
    t = text_model(tmp_path / "text", cameras, images, points)
    return text_to_binary(t, tmp_path / "bin")


CAMERA = "1 SIMPLE_PINHOLE 100 80 90 50 40\n"


def test_minimal_model_as_its_text(tmp_path):
    d = _text_model(tmp_path, CAMERA)
    _assert_identical(read_colmap(d), read_colmap(tmp_path / "text"))


@pytest.mark.parametrize(
    ("cameras", "match"),
    [
        ("1 OPENCV_FISHEYE 100 80 90 90 50 40 0 0 0 0\n", r"byte 8: camera 1 has COLMAP model "
                                                          r"OPENCV_FISHEYE.*supported"),
        ("1 FOV 100 80 90 90 50 40 0.1\n", r"model FOV.*supported: SIMPLE_PINHOLE"),
        ("1 FULL_OPENCV 100 80 90 90 50 40 0 0 0 0 0 0.1 0 0\n", r"rational terms k4, k5, k6"),
        ("1 SIMPLE_PINHOLE 100 80 -90 50 40\n", r"camera 1: focal length must be > 0"),
        ("1 SIMPLE_PINHOLE 100 0 90 50 40\n", r"WIDTH x HEIGHT = 100 x 0 is not an image size"),
        (CAMERA + CAMERA, r"cameras.bin, byte 56: camera id 1 appears twice"),
    ],
)  # fmt: skip
def test_refused_cameras(tmp_path, cameras, match):
    with pytest.raises(FileFormatError, match=match):
        read_colmap(_text_model(tmp_path, cameras))


@pytest.mark.parametrize(
    ("images", "points", "match"),
    [
        (None, "7 0 0 20 0 0 0 -1 1 0 3 0\n", r"points3D.bin, byte 8: point 7 is observed in "
                                              r"image 3, which is not in"),
        (None, "7 0 0 20 0 0 0 -1 1 0 2 4\n", r"POINT2D_IDX 4 is out of range for image 2"),
        (None, "7 0 0 20 0 0 0 -1 1 1 2 0\n", r"lists 2D point 1 of image 1.*disagree"),
        (None, "7 0 0 20 0 0 0 -1 1 0\n", r"links 2 2D points to 3D points but .* hold 1"),
        (None, "7 0 0 20 0 0 0 -1 1 0 2 0\n7 0 0 20 0 0 0 -1\n", r"POINT3D_ID 7 appears twice"),
        ("1 1 0 0 0 0 0 5 1 a.jpg\n10 20 7 30 40 -1\n2 1 0 0 0 1 0 5 2 b.jpg\n11 21 7\n", None,
         r"images.bin, byte 134: image 2 refers to camera 2"),
        ("1 2 0 0 0 0 0 5 1 a.jpg\n10 20 7 30 40 -1\n2 1 0 0 0 1 0 5 1 b.jpg\n11 21 7\n", None,
         r"byte 8: the quaternion of image 1 has norm 2"),
        ("1 1 0 0 0 0 0 5 1 a.jpg\n10 20 7 30 40 -1\n2 1 0 0 0 1 0 5 1 a.jpg\n11 21 7\n", None,
         r"NAME 'a.jpg' appears twice; read with image_key='id'"),
        ("1 1 0 0 0 0 0 5 1 a.jpg\n10 20 7 30 40 -1\n2 1 0 0 0 1 0 5 1 b.jpg\n11 21 7\n", None,
         None),
        ("1 1 0 0 0 0 nan 5 1 a.jpg\n10 20 7\n", None, r"byte 8: the pose holds NaN"),
        ("1 1 0 0 0 0 0 5 1 a.jpg\n", None, r"point 7 is observed in image 2, which is not in"),
        ("", None, r"images\.bin: no images"),
    ],
)  # fmt: skip
def test_inconsistent_models(tmp_path, images, points, match):
    d = _text_model(tmp_path, CAMERA, images, points)
    if match is None:
        _assert_identical(read_colmap(d), read_colmap(tmp_path / "text"))
        return
    with pytest.raises(FileFormatError, match=match):
        read_colmap(d)


def _good(tmp_path) -> Path:
    write_colmap(_all_models_block(), tmp_path / "good", binary=True)
    return tmp_path / "good"


@pytest.mark.parametrize("name", ["cameras.bin", "images.bin", "points3D.bin"])
def test_every_truncation_is_a_named_error(tmp_path, name):
    good = _good(tmp_path)
    data = (good / name).read_bytes()
    bad = tmp_path / "bad"
    shutil.copytree(good, bad)
    cuts = sorted(set(range(0, 80)) | set(range(0, len(data), 23)) | {len(data) - 1})
    for n in cuts:
        (bad / name).write_bytes(data[:n])
        with pytest.raises(FileFormatError, match=rf"{name}(, byte \d+)?: ") as info:
            read_colmap(bad)
        assert "truncated" in str(info.value) or "expected" in str(info.value) or (
            "disagree" in str(info.value) or "hold" in str(info.value)
        ), (n, str(info.value))


@pytest.mark.parametrize(
    ("name", "at", "value", "match"),
    [
        ("cameras.bin", 0, struct.pack("<Q", 2**62), r"cameras.bin, byte 0: the file says "
                                                     r"4611686018427387904 cameras, but"),
        ("images.bin", 0, struct.pack("<Q", 2**63), r"images.bin, byte 0: the file says .* images"),
        ("points3D.bin", 0, struct.pack("<Q", 2**64 - 1), r"points3D.bin, byte 0: the file says"),
        ("cameras.bin", 12, struct.pack("<i", 99), r"cameras.bin, byte 8: camera 10 has camera "
                                                   r"model id 99, which is not a COLMAP model"),
        ("cameras.bin", 12, struct.pack("<i", 5), r"COLMAP model OPENCV_FISHEYE, which the"),
        ("images.bin", 74, struct.pack("<Q", 2**61), r"images.bin, byte 74: image record 1 says "
                                                     r"2305843009213693952 2D points, but"),
        ("points3D.bin", 51, struct.pack("<Q", 2**61), r"points3D.bin, byte 51: point record 1 "
                                                       r"says 2305843009213693952 track elements"),
        ("points3D.bin", 8, struct.pack("<Q", 2**63 + 5), r"byte 8: POINT3D_ID "
                                                          r"9223372036854775813 is beyond"),
        ("images.bin", 72, b"\xff", r"images.bin, byte 72: the NAME of image 0 is not UTF-8"),
    ],
)  # fmt: skip
def test_damaged_fields_are_named(tmp_path, name, at, value, match):
    good = _good(tmp_path)
    data = bytearray((good / name).read_bytes())
    data[at : at + len(value)] = value
    (good / name).write_bytes(bytes(data))
    t0 = time.process_time()
    with pytest.raises(FileFormatError, match=match):
        read_colmap(good)
    assert time.process_time() - t0 < 5  # nothing of the size a count claims is allocated


def test_trailing_bytes_are_refused(tmp_path):
    good = _good(tmp_path)
    for name, what in (("cameras.bin", "cameras"), ("images.bin", "images"),
                       ("points3D.bin", "points")):  # fmt: skip
        data = (good / name).read_bytes()
        (good / name).write_bytes(data + b"\0" * 8)
        with pytest.raises(FileFormatError, match=rf"{name}, byte {len(data)}: 8 bytes after the "
                                                  rf"last of its \d+ {what}"):  # fmt: skip
            read_colmap(good)
        (good / name).write_bytes(data)


def test_points_in_another_order_are_read_the_same(tmp_path):
    """COLMAP writes the points in ascending id order; another order (or a point no image
    observes) is read record by record, to the same block."""
    t = tmp_path / "t"
    write_colmap(_all_models_block(point_ids=list(range(29, -1, -1))), t)
    text_to_binary(t, tmp_path / "b")  # the text model's order: descending ids
    ref = read_colmap(t)
    _assert_identical(read_colmap(tmp_path / "b"), ref)
    lines = (t / "points3D.txt").read_text() + "999 1 2 3 0 0 0 -1\n"  # observed by no image
    (t / "points3D.txt").write_text(lines)
    text_to_binary(t, tmp_path / "b")
    _assert_identical(read_colmap(tmp_path / "b"), read_colmap(t))


def test_grid_fit_reads_a_binary_model_as_the_text_model(tmp_path, cli):
    import photogeom as pg
    from photogeom.calibration import load_grids

    sim = pg.simulate.uav_block(
        "FC300S", seed=5, strips=2, images_per_strip=3, tie_points_per_image=40
    )
    block = pg.bundle_adjust(sim.block, snooping=False).block
    write_colmap(block, tmp_path / "t", drop_extras=True)
    write_colmap(block, tmp_path / "b", drop_extras=True, binary=True)
    grids = {}
    for k in ("t", "b"):
        code, _, err = cli("grid", "fit", tmp_path / k, "-o", tmp_path / f"{k}.json",
                           "--spacing", "400")  # fmt: skip
        assert code == 0, err
        grids[k] = load_grids(tmp_path / f"{k}.json")
    assert sorted(grids["b"]) == sorted(grids["t"]) and len(grids["b"]) == block.n_images
    for i, g in grids["t"].items():
        assert np.array_equal(grids["b"][i].nodes, g.nodes)
    victim = tmp_path / "b" / "images.bin"
    before = victim.read_bytes()
    code, _, err = cli("grid", "fit", tmp_path / "b", "--spacing", "400", "-o", victim)
    assert code == 2 and "is the input file RESIDUALS (images.bin of the block)" in err
    assert victim.read_bytes() == before
    # both models in one folder: the same model is read; a text model that differs is
    # refused in words a grid command (no format option) can follow
    for f in (tmp_path / "t").iterdir():
        shutil.copy(f, tmp_path / "b" / f.name)
    code, _, err = cli("grid", "fit", tmp_path / "b", "-o", tmp_path / "both.json",
                       "--spacing", "400")  # fmt: skip
    assert code == 0, err
    for i, g in load_grids(tmp_path / "both.json").items():
        assert np.array_equal(grids["b"][i].nodes, g.nodes)
    lines = (tmp_path / "b" / "images.txt").read_text().splitlines()
    row = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    f = lines[row].split()
    f[5] = repr(float(f[5]) + 0.01)  # one image's TX 1 cm off in the text model
    lines[row] = " ".join(f)
    (tmp_path / "b" / "images.txt").write_text("\n".join(lines) + "\n")
    frames = (tmp_path / "b" / "frames.txt").read_text().splitlines()  # and its frame
    k = next(i for i, line in enumerate(frames) if line.split()[0] == f[0])
    g = frames[k].split()
    g[6] = f[5]
    frames[k] = " ".join(g)
    (tmp_path / "b" / "frames.txt").write_text("\n".join(frames) + "\n")
    code, _, err = cli("grid", "fit", tmp_path / "b", "-o", tmp_path / "both.json",
                       "--spacing", "400")  # fmt: skip
    assert code == 2 and "they differ (their image poses first)" in err, err
    assert "remove the one not to read" in err and "kind=" not in err
