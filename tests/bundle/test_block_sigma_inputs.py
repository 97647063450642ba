"""Observation standard deviations: every way of setting them refuses what is not a positive,
finite number of pixels (Block.from_arrays and Block.with_observations, one shared check)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from photogeom.bundle import Block
from photogeom.camera.metashape import MetashapeCalibration
from photogeom.errors import InputError


def _block(sigma=0.5) -> Block:
    return Block.from_arrays(
        cameras={"c": MetashapeCalibration(400, 300, 500.0)},
        image_ids=[1, 2],
        image_camera=["c", "c"],
        exterior=[[0, 0, 50, 0, 0, 0], [10, 0, 50, 0, 0, 0]],
        point_ids=[7, 8],
        xyz=[[0, 0, 0], [5, 5, 0]],
        obs_image_ids=[1, 2, 1],
        obs_point_ids=[7, 7, 8],
        uv=[[1, 2], [3, 4], [5, 6]],
        sigma=sigma,
    )


@pytest.mark.parametrize("bad", [0.0, -0.5, math.nan, math.inf, [0.5, -1.0, 0.5]])
def test_with_observations_refuses_what_from_arrays_refuses(bad):
    with pytest.raises(InputError, match="sigma must be positive and finite"):
        _block(sigma=bad)
    b = _block()
    with pytest.raises(InputError, match="sigma must be positive and finite"):
        b.with_observations(sigma=bad)


def test_the_message_names_the_row():
    with pytest.raises(InputError, match=r"observation row 1 has -1\.0"):
        _block().with_observations(sigma=[0.5, -1.0, 0.5])


@given(st.lists(st.floats(min_value=1e-6, max_value=1e6), min_size=3, max_size=3))
def test_positive_sigmas_are_kept_exactly(values):
    b = _block().with_observations(sigma=values)
    assert b.observations.sigma.tolist() == values
    assert b.with_observations(sigma=2.0).observations.sigma.tolist() == [2.0, 2.0, 2.0]
