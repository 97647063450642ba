"""Block.from_arrays names the argument and the expected shape of wrongly shaped tables
(instead of numpy's broadcasting or reshaping errors)."""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.bundle import Block
from photogeom.camera.metashape import MetashapeCalibration
from photogeom.errors import InputError


def _kw(**changes):
    kw = dict(
        cameras={"c": MetashapeCalibration(400, 300, 500.0)},
        image_ids=[1, 2],
        image_camera=["c", "c"],
        exterior=[[0, 0, 50, 0, 0, 0], [10, 0, 50, 0, 0, 0]],
        point_ids=[7, 8, 9],
        xyz=[[0, 0, 0], [5, 5, 0], [1, 1, 1]],
        role=["control", "tie", "check"],
        point_sigma=[0.01, 0.01, 0.02],
        obs_image_ids=[1, 2],
        obs_point_ids=[7, 7],
        uv=[[1, 2], [3, 4]],
    )
    kw.update(changes)
    return kw


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"gnss": np.zeros((3, 3)), "gnss_sigma": 0.05}, r"gnss: shape \(3, 3\).*\(2, 3\)"),
        ({"gnss": np.zeros(6), "gnss_sigma": 0.05}, r"gnss: shape \(6,\).*\(2, 3\)"),
        ({"gnss": np.zeros((2, 3)), "gnss_sigma": [1, 2]}, r"gnss_sigma: shape \(2,\).*\(2, 3\)"),
        ({"imu": np.zeros((2, 2)), "imu_sigma": 0.01}, r"imu: shape \(2, 2\).*\(2, 3\)"),
        ({"point_sigma": [1, 2]}, r"point_sigma: shape \(2,\).*\(3, 3\)"),
        ({"point_sigma": np.ones((2, 3))}, r"point_sigma: shape \(2, 3\).*\(3, 3\)"),
        ({"sigma": [1, 2, 3]}, r"sigma: shape \(3,\).*one per observation \(2,\)"),
        ({"sigma": "wide"}, r"sigma: cannot be read as numbers"),
    ],
)
def test_wrong_shapes_are_named(changes, match):
    with pytest.raises(InputError, match=match):
        Block.from_arrays(**_kw(**changes))


def test_right_shapes_and_broadcasts_are_kept():
    b = Block.from_arrays(
        **_kw(gnss=[[0, 0, 50], [np.nan] * 3], gnss_sigma=[0.03, 0.03, 0.05], sigma=[0.5, 1.0])
    )
    assert b.gnss_sigma[0].tolist() == [0.03, 0.03, 0.05] and np.isnan(b.gnss_sigma[1]).all()
    assert b.point_sigma.tolist() == [[0.01, 0.01, 0.02]] * 3
    assert b.observations.sigma.tolist() == [0.5, 1.0]
    one = Block.from_arrays(
        **_kw(
            image_ids=[1],
            image_camera=["c"],
            exterior=[0, 0, 50, 0, 0, 0],
            obs_image_ids=[1, 1],
            gnss=[1, 2, 3],
            gnss_sigma=0.1,
        )
    )
    assert one.gnss.tolist() == [[1.0, 2.0, 3.0]]
