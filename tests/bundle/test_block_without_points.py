"""A block with images but no points or observations: empty id lists are accepted, and its
BAL file, which states no image size, is read back with the size given (or refused, saying
so)."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.bundle import Block
from photogeom.errors import FileFormatError


def _empty_block() -> Block:
    cal = pg.MetashapeCalibration(width=6000, height=4000, f=4000.0, k1=-0.05)
    return Block.from_arrays(
        cameras={1: cal},
        image_ids=[1],
        image_camera=[1],
        exterior=np.array([[10.0, 20.0, 100.0, 1.0, -2.0, 30.0]]),
        point_ids=[],  # numpy makes [] a float64 array: "ids must be integers or strings"
        xyz=np.zeros((0, 3)),
        obs_image_ids=[],
        obs_point_ids=[],
        uv=np.zeros((0, 2)),
    )


def test_empty_id_lists_make_a_block_without_points():
    block = _empty_block()
    assert (block.n_points, block.n_observations, block.n_images) == (0, 0, 1)


def test_bal_of_a_block_without_observations_needs_the_image_size(tmp_path):
    block = _empty_block()
    path = tmp_path / "empty.bal"
    pg.bundle.write_bal(block, path)
    # the image size is taken from the observations: with none, the reader says so (before:
    # "focal length f = 4000 px is more than 1000 image diagonals (3 px)")
    with pytest.raises(FileFormatError, match=r"no observations.*image_size=\(width, height\)"):
        pg.bundle.read_bal(path)
    back = pg.bundle.read_bal(path, image_size=(6000, 4000))
    cal = next(iter(back.cameras.values()))
    assert (cal.width, cal.height, cal.f, cal.k1) == (6000, 4000, 4000.0, -0.05)
    np.testing.assert_allclose(back.exterior[0, :3], [10.0, 20.0, 100.0], atol=1e-9)
