"""validate() names a remedy that works for each kind of weakly observed point, and
drop_weak_points(surveyed=True) is that remedy for control and check points."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom.errors import InputError

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block


def _one_ray_each():
    """The reported case: one control and one check point keep a single observation."""
    b = grid_block(seed=3, rows=2, cols=3, n_points=80, n_control=4, n_check=2)
    ctrl = b.point_ids[b.role == "control"][0]
    chk = b.point_ids[b.role == "check"][0]
    o = b.observations
    first = {}
    keep = np.ones(len(o), bool)
    for r, pid in enumerate(o.point_ids.tolist()):
        if pid in (ctrl, chk):
            keep[r] = pid not in first
            first.setdefault(pid, r)
    return b.select_observations(keep), ctrl, chk


def test_the_advice_for_control_and_check_points_works():
    b, ctrl, chk = _one_ray_each()
    weak = b.drop_weak_points()  # tie points only: the surveyed ones stay
    assert ctrl in weak.point_ids and chk in weak.point_ids
    with pytest.raises(InputError) as err:
        weak.validate()
    text = str(err.value)
    assert "2 control/check point(s)" in text and "drop_weak_points(surveyed=True)" in text
    assert f"{ctrl}" in text and f"{chk}" in text and "tie point(s)" not in text
    fixed = weak.drop_weak_points(surveyed=True)  # what the message says
    fixed.validate()
    assert ctrl not in fixed.point_ids and chk not in fixed.point_ids
    assert fixed.n_points == b.n_points - 2
    assert fixed.n_observations == b.n_observations - 2
    # the rows that stay refer to the same points as before
    assert np.array_equal(fixed.point_ids[fixed.obs_point], fixed.observations.point_ids)


def test_weak_tie_points_keep_their_advice():
    b = grid_block(seed=3, rows=2, cols=3, n_points=80, n_control=4, n_check=2)
    tie = b.point_ids[b.role == "tie"][0]
    keep = ~((b.observations.point_ids == tie) & (np.cumsum(b.observations.point_ids == tie) > 1))
    weak = b.select_observations(keep)
    with pytest.raises(InputError, match=r"^1 tie point\(s\) .*Block.drop_weak_points\(\)"):
        weak.validate()
    weak.drop_weak_points().validate()
    assert weak.drop_weak_points().n_points == b.n_points - 1


def test_select_points_keeps_each_kept_points_observations_and_coordinates():
    b = grid_block(seed=5, rows=2, cols=3, n_points=60, n_control=4, n_check=2)
    keep = np.random.default_rng(0).random(b.n_points) < 0.6
    new = b.select_points(keep)
    kept = set(b.point_ids[keep].tolist())
    assert new.point_ids.tolist() == [p for p in b.point_ids.tolist() if p in kept]
    # every observation of a kept point, in the block's order, with its pixels and image
    o, n = b.observations, new.observations
    rows = [r for r, p in enumerate(o.point_ids.tolist()) if p in kept]
    assert n.point_ids.tolist() == [o.point_ids[r] for r in rows]
    assert n.image_ids.tolist() == [o.image_ids[r] for r in rows]
    np.testing.assert_array_equal(n.uv, o.uv[rows])
    for pid in kept:
        i, j = b.point_ids.tolist().index(pid), new.point_ids.tolist().index(pid)
        np.testing.assert_array_equal(new.xyz[j], b.xyz[i])
        assert new.role[j] == b.role[i]
    with pytest.raises(ValueError, match="expected"):
        b.select_points(keep[:-1])
