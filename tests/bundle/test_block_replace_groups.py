"""``Block.replace`` with ``free`` / ``image_variant`` for some camera groups: the groups
left out keep their names, unknown groups and names are refused, and the adjustment of the
result frees exactly what was asked (counted in its redundancy)."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block

from photogeom.bundle import Block, bundle_adjust
from photogeom.errors import InputError


def _two_groups() -> Block:
    """A 3 x 4 block whose images alternate between two camera groups, "a" and "b"."""
    t = grid_block(seed=3, noise=0.3)
    o = t.observations
    cal = t.calibrations[0]
    return Block.from_arrays(
        cameras={"a": cal, "b": cal},
        image_ids=t.image_ids,
        image_camera=["a" if i % 2 == 0 else "b" for i in range(len(t.image_ids))],
        exterior=t.exterior,
        point_ids=t.point_ids,
        xyz=t.xyz,
        obs_image_ids=o.image_ids,
        obs_point_ids=o.point_ids,
        uv=o.uv,
        sigma=o.sigma,
        role=t.role,
        point_sigma=t.point_sigma,
        free={"a": ("f", "cx", "cy", "k1"), "b": ("f", "k1")},
    )


def test_image_variant_for_one_group_adjusts_and_keeps_the_other():
    b = _two_groups()
    v = b.replace(image_variant={"a": ("f",)})  # was a KeyError in the adjustment
    assert dict(v.image_variant) == {"a": ("f",), "b": ()}
    r0, r1 = bundle_adjust(b), bundle_adjust(v)
    n_a = int(np.sum(np.asarray(b.image_camera) == 0))
    # one focal length per image of group "a" instead of one for the group
    assert r0.redundancy - r1.redundancy == n_a - 1


def test_free_for_one_group_keeps_the_others_names():
    b = _two_groups()
    v = b.replace(free={"b": ["k1", "f"]})
    assert dict(v.free) == {"a": ("f", "cx", "cy", "k1"), "b": ("f", "k1")}  # canonical order
    w = b.replace(free=("f",))  # a sequence: every group
    assert dict(w.free) == {"a": ("f",), "b": ("f",)}


@pytest.mark.parametrize(
    "changes, words",
    [
        ({"image_variant": {"c": ("f",)}}, "unknown camera group"),
        ({"image_variant": {"a": ("k1",)}}, "unknown parameter"),
        ({"free": {"a": ("focal",)}}, "unknown parameter"),
    ],
)
def test_unknown_groups_and_names_are_refused(changes, words):
    with pytest.raises(InputError, match=words):
        _two_groups().replace(**changes)
