"""COLMAP 3.12 and later write rigs (``rigs.txt`` / ``rigs.bin``) and frames beside the
model. photogeom reads each image with the pose in ``images.txt`` / ``images.bin``, which
COLMAP composes from the image's frame and rig (COLMAP's format documentation: newer
``cameras`` and ``images`` files are compatible with old ones), and adjusts it as an
independent image: a model with a rig of several cameras is read to the same block as
without its rig files, and a ``ColmapRigWarning`` says that the rig is not a constraint
(before: nothing was said)."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from photogeom import MetashapeCalibration
from photogeom.bundle import read_colmap, write_colmap
from photogeom.bundle.io_colmap import ColmapRigWarning, rig_sizes
from photogeom.errors import FileFormatError

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block

CAL = MetashapeCalibration(3000, 2000, 2400.0, k1=-0.08, k2=0.03)


def _pose(line: str):
    t = line.split()
    q = np.array([float(x) for x in t[1:5]])
    return Rotation.from_quat(q[[1, 2, 3, 0]]), np.array([float(x) for x in t[5:8]])


def _tokens(rot, t) -> str:
    x, y, z, w = rot.as_quat()
    return " ".join(repr(float(v)) for v in (w, x, y, z, *t))


def _rig_model(folder: Path) -> None:
    """A model written by photogeom made into one of COLMAP 3.12 with a rig: images 1 and 2
    are the two cameras of rig 1 in frame 1 (camera 2 a copy of camera 1), image 3 the
    reference camera alone in frame 3; every pose in images.txt is the composition of its
    frame's and its sensor's, as COLMAP writes it."""
    write_colmap(grid_block(2, rows=1, cols=3, n_points=40, cal=CAL), folder, drop_extras=True)
    cams = (folder / "cameras.txt").read_text().splitlines()
    cam1 = next(c for c in cams if c.startswith("1 "))
    (folder / "cameras.txt").write_text("\n".join([*cams, "2" + cam1[1:]]) + "\n")
    lines = (folder / "images.txt").read_text().splitlines()
    heads = [k for k, ln in enumerate(lines) if ln and not ln.startswith("#")][::2]
    poses = [_pose(lines[k]) for k in heads]
    tok = lines[heads[1]].split()
    tok[8] = "2"  # image 2 taken by camera 2
    lines[heads[1]] = " ".join(tok)
    (folder / "images.txt").write_text("\n".join(lines) + "\n")
    (r1, t1), (r2, t2), (r3, t3) = poses
    rel = r2 * r1.inv()  # sensor 2 from rig (= camera 1)
    rel_t = t2 - rel.apply(t1)
    (folder / "rigs.txt").write_text(
        "# Number of rigs: 1\n" f"1 2 CAMERA 1 CAMERA 2 1 {_tokens(rel, rel_t)}\n"
    )
    (folder / "frames.txt").write_text(
        "# Number of frames: 2\n"
        f"1 1 {_tokens(r1, t1)} 2 CAMERA 1 1 CAMERA 2 2\n"
        f"3 1 {_tokens(r3, t3)} 1 CAMERA 1 3\n"
    )


@pytest.fixture
def rig_model(tmp_path):
    folder = tmp_path / "text"
    _rig_model(folder)
    return folder


def _plain(folder: Path, tmp_path: Path) -> Path:
    """The same model without its rig and frame files (a model of COLMAP before 3.12)."""
    plain = tmp_path / "plain"
    plain.mkdir()
    for name in ("cameras.txt", "images.txt", "points3D.txt"):
        (plain / name).write_bytes((folder / name).read_bytes())
    return plain


def test_a_text_model_with_a_rig_is_read_as_independent_images_and_says_so(rig_model, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        want = read_colmap(_plain(rig_model, tmp_path))  # no rig file: no warning
    with pytest.warns(ColmapRigWarning, match=r"rigs.txt holds 1 rig\(s\) of several cameras"):
        got = read_colmap(rig_model)
    np.testing.assert_array_equal(got.exterior, want.exterior)
    np.testing.assert_array_equal(got.observations.uv, want.observations.uv)
    assert rig_sizes(rig_model, binary=False) == {1: 2}


def test_colmap_reads_the_rig_model_with_the_poses_of_images_txt(rig_model, tmp_path):
    # the peer: pycolmap composes each image's pose from its frame and rig; they are the
    # poses of images.txt that photogeom reads, and its binary model has the same rig
    pycolmap = pytest.importorskip("pycolmap")
    rec = pycolmap.Reconstruction(str(rig_model))
    assert rec.num_rigs() == 1 and rec.num_frames() == 2
    block = read_colmap(_plain(rig_model, tmp_path))
    for image in rec.images.values():
        if not image.has_pose:
            continue
        k = block.image_ids.tolist().index(image.name)
        centre = -image.cam_from_world().rotation.matrix().T @ image.cam_from_world().translation
        np.testing.assert_allclose(block.exterior[k, :3], centre, rtol=0, atol=1e-9)
    binary = tmp_path / "bin"
    binary.mkdir()
    rec.write_binary(str(binary))
    assert rig_sizes(binary, binary=True) == {1: 2}
    with pytest.warns(ColmapRigWarning, match=r"rigs.bin holds 1 rig\(s\)"):
        read_colmap(binary)


def test_a_damaged_rig_file_is_refused_by_name(rig_model):
    (rig_model / "rigs.txt").write_text("1 x CAMERA 1\n")
    with pytest.raises(FileFormatError, match=r"rigs.txt, line 1: expected RIG_ID NUM_SENSORS"):
        read_colmap(rig_model)


def test_photogeoms_own_models_have_trivial_rigs_and_no_warning(tmp_path):
    write_colmap(grid_block(2, rows=1, cols=3, n_points=40, cal=CAL), tmp_path / "m",
                 drop_extras=True, binary=True)  # fmt: skip
    assert rig_sizes(tmp_path / "m", binary=True) == {1: 1}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_colmap(tmp_path / "m")


def _shift_image(folder: Path, image: int, dx: float) -> None:
    """Move image ``image``'s TX in images.txt by ``dx``, as a tool that rewrites
    images.txt and leaves the frames (COLMAP before 3.12, a script) does."""
    lines = (folder / "images.txt").read_text().splitlines()
    for k in [k for k, ln in enumerate(lines) if ln and not ln.startswith("#")][::2]:
        tok = lines[k].split()
        if tok[0] == str(image):
            tok[5] = repr(float(tok[5]) + dx)
            lines[k] = " ".join(tok)
    (folder / "images.txt").write_text("\n".join(lines) + "\n")


def _centre(rec, name: str) -> np.ndarray:
    pose = next(im for im in rec.images.values() if im.name == name).cam_from_world()
    return -pose.rotation.matrix().T @ pose.translation


def test_images_txt_contradicting_its_frames_is_refused_naming_files_and_images(
    rig_model, tmp_path
):
    # image 2 (camera 2, composed through the rig's sensor pose) moved by 0.5 in images.txt:
    # COLMAP 3.12+ reads the frame's pose, photogeom would read images.txt's (before: read
    # without a word, a block 0.5 units off what COLMAP reads from the same folder)
    pycolmap = pytest.importorskip("pycolmap")
    want = read_colmap(_plain(rig_model, tmp_path))
    _shift_image(rig_model, 2, 0.5)
    (tmp_path / "moved").mkdir()
    moved = read_colmap(_plain(rig_model, tmp_path / "moved"))
    k = want.image_ids.tolist().index("img001")
    assert np.linalg.norm(moved.exterior[k, :3] - want.exterior[k, :3]) == pytest.approx(0.5)
    # the peer reads the frames' pose, not images.txt's
    rec = pycolmap.Reconstruction(str(rig_model))
    np.testing.assert_allclose(_centre(rec, "img001"), want.exterior[k, :3], atol=1e-9)
    with pytest.raises(FileFormatError) as err:
        read_colmap(rig_model)
    msg = str(err.value)
    assert "the poses of 1 image(s) contradict" in msg and "2 'img001'" in msg
    assert "frames.txt" in msg and "rigs.txt" in msg and "remove rigs.txt and frames.txt" in msg
    assert "0.5 model units apart" in msg
    # the remedy: without the rig and frame files COLMAP and photogeom read images.txt alike
    (rig_model / "rigs.txt").unlink()
    (rig_model / "frames.txt").unlink()
    np.testing.assert_array_equal(read_colmap(rig_model).exterior, moved.exterior)
    rec = pycolmap.Reconstruction(str(rig_model))
    np.testing.assert_allclose(_centre(rec, "img001"), moved.exterior[k, :3], atol=1e-9)


def test_a_turn_below_the_tolerance_is_read_and_above_it_refused(rig_model):
    lines = (rig_model / "images.txt").read_text().splitlines()
    k = next(k for k, ln in enumerate(lines) if ln.startswith("3 "))
    r, t = _pose(lines[k])
    for angle, refused in ((1e-8, False), (1e-5, True)):
        turned = Rotation.from_rotvec([0.0, 0.0, angle]) * r
        ln = [*lines[:k], "3 " + _tokens(turned, t) + " 1 img002", *lines[k + 1 :]]
        (rig_model / "images.txt").write_text("\n".join(ln) + "\n")
        if refused:
            with pytest.raises(FileFormatError, match=r"image 3 'img002': 0.000573 deg"):
                read_colmap(rig_model)
        else:
            with pytest.warns(ColmapRigWarning):
                read_colmap(rig_model)


def test_an_image_in_no_frame_is_refused_as_colmap_cannot_read_it(rig_model):
    pycolmap = pytest.importorskip("pycolmap")
    frames = (rig_model / "frames.txt").read_text().splitlines()
    (rig_model / "frames.txt").write_text("\n".join(f for f in frames if not f.startswith("3 ")))
    with pytest.raises(Exception):  # noqa: B017 - pycolmap's own error (unordered_map::at)
        pycolmap.Reconstruction(str(rig_model))
    with pytest.raises(FileFormatError, match=r"1 image\(s\) are in no frame of frames.txt "
                       r"\(images 3 'img002'\)"):  # fmt: skip
        read_colmap(rig_model)


def test_a_binary_model_whose_images_bin_contradicts_its_frames_is_refused(rig_model, tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    binary = tmp_path / "bin"
    binary.mkdir()
    pycolmap.Reconstruction(str(rig_model)).write_binary(str(binary))
    with pytest.warns(ColmapRigWarning):
        read_colmap(binary)  # as COLMAP wrote it: agrees
    data = bytearray((binary / "images.bin").read_bytes())
    # the first image's TX: after the count (8), IMAGE_ID (4) and QW QX QY QZ (32)
    image = int(np.frombuffer(data, "<u4", 1, 8)[0])
    tx = np.frombuffer(data, "<f8", 1, 44)[0]
    data[44:52] = np.float64(tx + 2.0).tobytes()
    (binary / "images.bin").write_bytes(bytes(data))
    with pytest.raises(FileFormatError, match=rf"images.bin and the frames disagree.*image "
                       rf"{image} 'img00\d': 0 deg and 2 model units apart.*remove rigs.bin "
                       r"and frames.bin"):  # fmt: skip
        read_colmap(binary)


@pytest.mark.parametrize("binary", [False, True])
def test_rigs_without_frames_are_refused_as_colmap_cannot_read_them(rig_model, tmp_path, binary):
    # COLMAP 3.12+ writes rigs and frames together; with rigs and no frames it looks up each
    # image's frame and fails (before: photogeom read such a folder without a word)
    pycolmap = pytest.importorskip("pycolmap")
    folder, ext = rig_model, ".txt"
    if binary:
        folder, ext = tmp_path / "bin", ".bin"
        folder.mkdir()
        pycolmap.Reconstruction(str(rig_model)).write_binary(str(folder))
    (folder / f"frames{ext}").unlink()
    with pytest.raises(Exception):  # noqa: B017 - pycolmap's own error (unordered_map::at)
        pycolmap.Reconstruction(str(folder))
    with pytest.raises(FileFormatError, match=rf"rigs{ext} holds 1 rig\(s\) but the model has "
                       rf"no frames{ext}.*remove rigs{ext} if images{ext} holds the poses "
                       "meant"):  # fmt: skip
        read_colmap(folder)
    # the remedy: without the rigs, COLMAP and photogeom read the poses of the images file
    (folder / f"rigs{ext}").unlink()
    rec = pycolmap.Reconstruction(str(folder))
    block = read_colmap(folder)
    np.testing.assert_allclose(_centre(rec, "img001"), block.exterior[1, :3], atol=1e-9)


def test_a_rigs_file_without_rigs_and_without_frames_is_read_as_colmap_reads_it(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    folder = tmp_path / "m"
    write_colmap(grid_block(2, rows=1, cols=3, n_points=40, cal=CAL), folder, drop_extras=True)
    (folder / "frames.txt").unlink()
    (folder / "rigs.txt").write_text("# Number of rigs: 0\n")
    assert pycolmap.Reconstruction(str(folder)).num_images() == 3  # an older model's reading
    assert read_colmap(folder).n_images == 3


@pytest.mark.parametrize(
    ("edit", "count", "said"),
    [
        (lambda t: t[:2] + "9" + t[3:], 2,
         r"image 1 'img000': rig 9, which rigs.txt does not hold; image 2 'img001': rig 9"),
        (lambda t: t.replace("CAMERA 1 1", "CAMERA 7 1"), 1,
         r"image 1 'img000': camera 7, which is no sensor of rig 1"),
    ],
)  # fmt: skip
def test_frames_in_rigs_the_rigs_file_does_not_give_are_refused(rig_model, edit, count, said):
    # frame 1 in rig 9 (not in rigs.txt), or its image taken by camera 7 (no sensor of rig
    # 1): COLMAP cannot read the model ("Rig with ID 9 does not exist", "rig.HasSensor");
    # before, photogeom read it without a word (the poses of those images went unchecked)
    pycolmap = pytest.importorskip("pycolmap")
    lines = (rig_model / "frames.txt").read_text().splitlines()
    lines = [edit(ln) if ln.startswith("1 1 ") else ln for ln in lines]
    (rig_model / "frames.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(Exception):  # noqa: B017 - pycolmap's own error
        pycolmap.Reconstruction(str(rig_model))
    with pytest.raises(FileFormatError, match=rf"frames.txt places {count} image\(s\) in rigs "
                       rf"that rigs.txt does not give them \({said}.*\); COLMAP cannot read "
                       "the model either. If images.txt holds the poses meant, remove rigs.txt "
                       "and frames.txt"):  # fmt: skip
        read_colmap(rig_model)
