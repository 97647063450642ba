"""COLMAP ids and names survive read -> adjust -> write.

IMAGE_ID and CAMERA_ID are keys of COLMAP's database and NAME the image's file name; the
block keys its images by one of IMAGE_ID and NAME, and the writer used to number the other
(IMAGE_ID 101 written as 1 with the default name key; NAME IMG_0.JPG written as "101" with
``--image-key id``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.bundle import read_colmap, write_colmap

IMAGE_IDS = [101, 205, 333, 334, 900, 4000]
NAMES = [f"IMG_{k}.JPG" for k in range(6)]
CAMERA_IDS = [7, 12, 7, 12, 7, 12]
W, H, F = 4000, 3000, 3000.0


def _model(d: Path) -> Path:
    """A hand-written COLMAP text model: non-consecutive ids, names unlike the ids."""
    rng = np.random.default_rng(11)
    d.mkdir()
    (d / "cameras.txt").write_text(
        "# Camera list\n"
        f"7 SIMPLE_RADIAL {W} {H} {F} 2000.5 1500.5 0.0\n"
        f"12 PINHOLE {W} {H} {F} {F} 2001.5 1499.5\n"
    )
    pid = np.arange(40) * 7 + 1000
    xyz = np.column_stack(
        [rng.uniform(-40, 40, 40), rng.uniform(-30, 30, 40), rng.normal(0, 3, 40)]
    )
    centres = np.column_stack([np.linspace(-15, 15, 6), rng.uniform(-5, 5, 6), np.full(6, 120.0)])
    R = np.diag([1.0, -1.0, -1.0])  # looking straight down; q = (0, 1, 0, 0)
    img_lines, tracks = [], {int(p): [] for p in pid}
    for iid, cid, name, c in zip(IMAGE_IDS, CAMERA_IDS, NAMES, centres):
        T = (-R @ c).tolist()
        P = (xyz - c) @ R.T
        uv = F * P[:, :2] / P[:, 2:] + [2000.5, 1500.5] + rng.normal(0, 0.3, (40, 2))
        img_lines.append(f"{iid} 0 1 0 0 {T[0]!r} {T[1]!r} {T[2]!r} {cid} {name}")
        img_lines.append(" ".join(f"{u!r} {v!r} {p}" for (u, v), p in zip(uv.tolist(), pid)))
        for j, p in enumerate(pid):
            tracks[int(p)] += [iid, j]
    (d / "images.txt").write_text("# Image list\n" + "\n".join(img_lines) + "\n")
    (d / "points3D.txt").write_text(
        "# 3D point list\n"
        + "".join(
            f"{p} {x!r} {y!r} {z!r} 0 0 0 -1 {' '.join(map(str, tracks[int(p)]))}\n"
            for p, (x, y, z) in zip(pid, xyz.tolist())
        )
    )
    return d


def _heads(d: Path) -> list[tuple[int, int, str]]:
    rows = [ln.split() for ln in (d / "images.txt").read_text().splitlines() if ln[:1] != "#"]
    return [(int(t[0]), int(t[8]), t[9]) for t in rows[0::2]]


def _point_ids(d: Path) -> list[int]:
    lines = (d / "points3D.txt").read_text().splitlines()
    return sorted(int(ln.split()[0]) for ln in lines if ln[:1] != "#")


def _track_images(d: Path) -> set[int]:
    lines = (d / "points3D.txt").read_text().splitlines()
    return {int(t) for ln in lines if ln[:1] != "#" for t in ln.split()[8::2]}


@pytest.mark.parametrize("image_key", ["name", "id"])
def test_read_adjust_write_keeps_image_ids_names_camera_and_point_ids(tmp_path, image_key):
    src = _model(tmp_path / "in")
    block = read_colmap(src, image_key=image_key)
    fit = pg.bundle_adjust(block, datum="free")
    out = write_colmap(fit.block, tmp_path / "out")
    assert _heads(out) == list(zip(IMAGE_IDS, CAMERA_IDS, NAMES))
    assert _point_ids(out) == _point_ids(src)
    assert _track_images(out) == set(IMAGE_IDS)
    frames = [ln.split() for ln in (out / "frames.txt").read_text().splitlines() if ln[:1] != "#"]
    assert [int(t[0]) for t in frames] == IMAGE_IDS
    # and read back: the same keys
    again = read_colmap(out, image_key=image_key)
    assert again.image_ids.tolist() == block.image_ids.tolist()


@pytest.mark.parametrize("image_key", ["name", "id"])
def test_cli_adjust_to_colmap_keeps_ids(tmp_path, cli, image_key):
    src = _model(tmp_path / "in")
    out = tmp_path / "out"
    code, _, err = cli(
        "bundle", "adjust", src, "--datum", "free", "-o", out, "--output-format", "colmap",
        "--image-key", image_key,
    )
    assert code == 0, err
    assert _heads(out) == list(zip(IMAGE_IDS, CAMERA_IDS, NAMES))
    assert _point_ids(out) == _point_ids(src)


def test_pycolmap_reads_the_ids_and_names(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    src = _model(tmp_path / "in")
    out = write_colmap(pg.bundle_adjust(read_colmap(src), datum="free").block, tmp_path / "out")
    rec = pycolmap.Reconstruction(str(out))
    assert {i: im.name for i, im in rec.images.items()} == dict(zip(IMAGE_IDS, NAMES))
    assert {i: im.camera_id for i, im in rec.images.items()} == dict(zip(IMAGE_IDS, CAMERA_IDS))
    assert sorted(rec.cameras) == [7, 12]
    assert sorted(rec.points3D) == _point_ids(src)


def test_renamed_images_are_numbered_as_before(tmp_path):
    """Image ids the COLMAP identity does not know: the writer's numbering, not stale ids."""
    block = read_colmap(_model(tmp_path / "in"))
    b = block.replace(image_ids=np.array([f"new{k}" for k in range(6)]))
    out = write_colmap(b, tmp_path / "out")
    assert [h[0] for h in _heads(out)] == [1, 2, 3, 4, 5, 6]
    assert [h[2] for h in _heads(out)] == [f"new{k}" for k in range(6)]


@pytest.mark.parametrize("image_key", ["name", "id"])
def test_colmap_csv_adjust_colmap_keeps_ids(tmp_path, image_key):
    """Through a CSV block (a person edits it), the images.csv columns colmap_image_id and
    colmap_name carry IMAGE_ID and NAME back to COLMAP."""
    src = _model(tmp_path / "in")
    block = read_colmap(src, image_key=image_key)
    pg.bundle.write_csv_block(block, tmp_path / "csv")
    text = (tmp_path / "csv" / "images.csv").read_text()
    assert "colmap_image_id,colmap_name" in text
    fit = pg.bundle_adjust(pg.bundle.read_csv_block(tmp_path / "csv"), datum="free")
    out = write_colmap(fit.block, tmp_path / "out")
    assert _heads(out) == list(zip(IMAGE_IDS, CAMERA_IDS, NAMES))
    assert _point_ids(out) == _point_ids(src)


def _csv_with(tmp_path, edit) -> Path:
    pg.bundle.write_csv_block(read_colmap(_model(tmp_path / "in")), tmp_path / "csv")
    f = tmp_path / "csv" / "images.csv"
    f.write_text(edit(f.read_text()))
    return tmp_path / "csv"


@pytest.mark.parametrize(
    "edit,match",
    [
        (lambda t: t.replace(",colmap_name", ",name"), "colmap_name is missing"),
        (lambda t: t.replace(",205,", ",101,"), r"line 4: colmap_image_id '101'"),
        (lambda t: t.replace(",205,", ",-1,"), r"colmap_image_id '-1': COLMAP image ids"),
        (lambda t: t.replace(",205,", ',"205",'), r"quoted cells.*write them unquoted"),
        (lambda t: t.replace(",205,", ",0205,"), r"line 4: colmap_image_id '0205'"),
    ],
)
def test_colmap_columns_refused_with_named_errors(tmp_path, edit, match):
    from photogeom.errors import FileFormatError

    d = _csv_with(tmp_path, edit)
    with pytest.raises(FileFormatError, match=match):
        pg.bundle.read_csv_block(d)
