"""POINT3D_ID 2^63 - 1, which read_colmap reads, is written back as it is.

Before: the writer kept integer point ids below 2^63 - 1 only, so a model holding the id
9223372036854775807 (read as such) was written with all its point ids renumbered 1, 2, ...
(40 points of a COLMAP model: 1000 .. 1266 and 2^63 - 1 became 1 .. 40).
"""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.bundle import Block, read_colmap, write_colmap
from photogeom.camera.metashape import MetashapeCalibration

BIG = 2**63 - 1
POINT_IDS = [0, 1000, 2**53 + 1, BIG]


def _block() -> Block:
    rng = np.random.default_rng(4)
    xyz = np.column_stack([rng.uniform(-20, 20, 4), rng.uniform(-20, 20, 4), np.zeros(4)])
    centres = np.array([[-5.0, 0.0, 100.0], [5.0, 0.0, 100.0]])
    f, w, h = 3000.0, 4000, 3000
    uv = np.concatenate(
        [f * (xyz[:, :2] - c[:2]) * [1, -1] / c[2] + [w / 2 - 0.5, h / 2 - 0.5] for c in centres]
    )
    return Block.from_arrays(
        cameras={7: MetashapeCalibration(w, h, f)},
        image_ids=[101, 205],
        image_camera=[7, 7],
        exterior=np.column_stack([centres, np.zeros((2, 3))]),
        point_ids=POINT_IDS,
        xyz=xyz,
        obs_image_ids=np.repeat([101, 205], 4),
        obs_point_ids=POINT_IDS * 2,
        uv=uv,
        sigma=1.0,
        free=("f",),
    )


def _point_ids(d) -> list[int]:
    lines = (d / "points3D.txt").read_text().splitlines()
    return sorted(int(ln.split()[0]) for ln in lines if ln[:1] != "#")


def test_largest_point_id_round_trips(tmp_path):
    first = write_colmap(_block(), tmp_path / "a")
    assert _point_ids(first) == POINT_IDS
    block = read_colmap(first, image_key="id")
    assert block.point_ids.tolist() == POINT_IDS
    again = write_colmap(block, tmp_path / "b")
    for name in ("points3D.txt", "images.txt", "cameras.txt"):
        assert (again / name).read_text() == (first / name).read_text()


def test_pycolmap_reads_the_largest_point_id(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    out = write_colmap(_block(), tmp_path / "m")
    assert sorted(pycolmap.Reconstruction(str(out)).points3D) == POINT_IDS
