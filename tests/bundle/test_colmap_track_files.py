"""COLMAP text and binary models that COLMAP's reader takes and a block cannot hold as written:
an images.txt cut short after an image's header line, and a track naming one image twice.

pycolmap is the peer: it reads each file, and the tests check what it reads of it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from photogeom.bundle import read_colmap
from photogeom.errors import FileFormatError

pycolmap = pytest.importorskip("pycolmap")

W, H, F = 3000, 2000, 2500.0
IMAGE_IDS = [3, 5, 8]


def _model(d: Path, *, extra_image: str = "", end: str = "\n") -> Path:
    """A COLMAP text model: 3 images looking down at 12 points (every point in every
    image); ``extra_image``: one more images.txt header line, written after the others and
    followed by ``end``."""
    rng = np.random.default_rng(5)
    d.mkdir()
    (d / "cameras.txt").write_text(f"# Camera list\n1 SIMPLE_PINHOLE {W} {H} {F} 1500 1000\n")
    pid = np.arange(12) + 100
    xyz = np.column_stack(
        [rng.uniform(-20, 20, 12), rng.uniform(-15, 15, 12), rng.normal(0, 2, 12)]
    )
    R = np.diag([1.0, -1.0, -1.0])  # looking straight down: q = (0, 1, 0, 0)
    lines, tracks = ["# Image list"], {int(p): [] for p in pid}
    for iid, x in zip(IMAGE_IDS, (-8.0, 0.0, 8.0)):
        c = np.array([x, 1.0, 90.0])
        T = (-R @ c).tolist()
        P = (xyz - c) @ R.T
        uv = F * P[:, :2] / P[:, 2:] + [1500.0, 1000.0] + rng.normal(0, 0.3, (12, 2))
        lines.append(f"{iid} 0 1 0 0 {T[0]!r} {T[1]!r} {T[2]!r} 1 IMG_{iid}.JPG")
        lines.append(" ".join(f"{u!r} {v!r} {p}" for (u, v), p in zip(uv.tolist(), pid)))
        for j, p in enumerate(pid):
            tracks[int(p)] += [iid, j]
    text = "\n".join(lines) + "\n"
    (d / "images.txt").write_text(text + (extra_image + end if extra_image else ""))
    (d / "points3D.txt").write_text(
        "# 3D point list\n"
        + "".join(
            f"{p} {x!r} {y!r} {z!r} 0 0 0 -1 {' '.join(map(str, tracks[int(p)]))}\n"
            for p, (x, y, z) in zip(pid, xyz.tolist())
        )
    )
    return d


LAST = "9 0 1 0 0 0.0 1.0 -90.0 1 IMG_9.JPG"


@pytest.mark.parametrize("end", ["\n", ""])
def test_images_txt_cut_after_a_header_line_is_refused_naming_it(tmp_path, end):
    # the last image's header line without its POINTS2D line: COLMAP drops the image
    d = _model(tmp_path / "m", extra_image=LAST, end=end)
    assert pycolmap.Reconstruction(str(d)).num_images() == 3
    with pytest.raises(FileFormatError, match=r"images\.txt, line 8: the file ends after") as e:
        read_colmap(d)
    assert "POINTS2D" in str(e.value) and "empty line after line 8" in str(e.value)


def test_images_txt_with_the_empty_points2d_line_keeps_the_image(tmp_path):
    # the same image with its (empty) POINTS2D line, as COLMAP writes it: both read 4 images
    d = _model(tmp_path / "m", extra_image=LAST, end="\n\n")
    assert pycolmap.Reconstruction(str(d)).num_images() == 4
    block = read_colmap(d, image_key="id")
    assert sorted(block.image_ids.tolist()) == [3, 5, 8, 9]
    assert len(block.obs_image) == 36


def _image_twice(d: Path) -> Path:
    """The model of :func:`_model` with a 13th 2D point of image 3 linked to point 100, which
    image 3 sees at its 2D point 0 already: point 100's track names image 3 twice."""
    lines = (d / "images.txt").read_text().splitlines()
    lines[2] += " 1501.25 1000.75 100"
    (d / "images.txt").write_text("\n".join(lines) + "\n")
    pts = (d / "points3D.txt").read_text().splitlines()
    pts[1] += " 3 12"
    (d / "points3D.txt").write_text("\n".join(pts) + "\n")
    return d


def test_a_track_naming_an_image_twice_is_refused_naming_lines_and_ids(tmp_path):
    d = _image_twice(_model(tmp_path / "m"))
    peer = pycolmap.Reconstruction(str(d))  # COLMAP keeps both observations
    assert peer.points3D[100].track.length() == 4
    assert sorted(e.image_id for e in peer.points3D[100].track.elements) == [3, 3, 5, 8]
    with pytest.raises(FileFormatError) as e:
        read_colmap(d)
    msg = str(e.value)
    assert "points3D.txt, line 2: the track of point 100 names image 3 (IMG_3.JPG) twice" in msg
    assert "POINT2D_IDX 0 and 12" in msg and "images.txt, line 3" in msg
    assert "remove one of the two from the track" in msg


def test_a_binary_track_naming_an_image_twice_is_refused_as_the_text_one(tmp_path):
    d = _image_twice(_model(tmp_path / "m"))
    out = tmp_path / "bin"
    out.mkdir()
    pycolmap.Reconstruction(str(d)).write_binary(str(out))  # COLMAP's own binary model
    with pytest.raises(FileFormatError) as e:
        read_colmap(out)
    msg = str(e.value)
    assert "points3D.bin, byte " in msg
    assert "the track of point 100 names image 3 (IMG_3.JPG) twice, POINT2D_IDX 0 and 12" in msg
    assert "images.bin, byte " in msg


def test_bundle_convert_of_a_track_naming_an_image_twice_names_the_file(tmp_path, cli):
    # before, the block was read and written as CSV and Bundler blocks that their own
    # readers refuse, and bundle adjust refused it naming no file
    d = _image_twice(_model(tmp_path / "m"))
    code, _out, err = cli("bundle", "convert", d, tmp_path / "csv", "--to", "csv")
    assert code != 0
    assert "points3D.txt, line 2: the track of point 100 names image 3" in " ".join(err.split())
    assert not (tmp_path / "csv").exists()
