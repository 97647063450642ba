"""A blunder on a poorly controlled image observation (a point seen in two
images, the error along the base) passed the bundle adjustment's w-test and nothing said so;
now the observations with a redundancy number below 0.1 are listed with a note and their
minimal detectable bias."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.adjust.snooping import noncentrality


@pytest.fixture(scope="module")
def block():
    return pg.simulate.uav_block("FC300S", seed=3, local_field=0.0, sigma=0.5)


def test_blunder_on_a_two_ray_point_is_reported_as_undetectable(block):
    fit = pg.bundle_adjust(block.block)
    red = fit.snooping["redundancy_numbers"]
    k = int(np.flatnonzero(np.nan_to_num(red[:, 0], nan=1.0) < 0.01)[0])
    uv = block.block.observations.uv.copy()
    uv[k, 0] += 20.0  # 40 sigma
    bad = pg.bundle_adjust(block.block.with_observations(uv=uv))
    o = block.block.observations
    key = (o.image_ids[k].item(), o.point_ids[k].item())
    sn = bad.snooping
    assert np.all(np.abs(sn["w"][k]) < sn["critical_value"])  # passes the w-test ...
    assert key not in {(a, b) for a, b, _ in sn["flagged"]}
    assert key in sn["poorly_controlled"]  # ... and is named as poorly controlled
    assert sn["mdb"][k, 0] == pytest.approx(noncentrality(0.001) / np.sqrt(red[k, 0]), rel=0.2)
    note = next(n for n in bad.notes if "poorly controlled" in n)
    assert f"{len(sn['poorly_controlled'])} image observation(s)" in note
    assert "two images" in note
    assert list(key) in bad.to_dict()["snooping"]["poorly_controlled"]
    assert "poorly controlled" in bad.summary()
    # every listed observation has r < 0.1 in u or v, every other one not
    in_adj = bad.in_adjustment
    poor = np.any(sn["redundancy_numbers"] < 0.1, axis=1) & in_adj
    assert poor.sum() == len(sn["poorly_controlled"])
