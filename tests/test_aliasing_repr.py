"""The repr of a result stays short whatever the size of the problem."""

from __future__ import annotations

import re

import numpy as np
import pytest

import photogeom as pg
from photogeom.records import compact_repr


def _relative(n, seed=0):
    rng = np.random.default_rng(seed)
    io = pg.InteriorOrientation(100.0)
    e1 = pg.ExteriorOrientation.from_degrees(0, 0, 800, 1, -2, 3)
    e2 = pg.ExteriorOrientation.from_degrees(300, 10, 805, -2, 1, 5)
    g = np.column_stack([rng.uniform(-100, 400, (n, 2)), rng.uniform(0, 80, n)])
    xy1 = pg.project(g, io, e1) + rng.normal(scale=0.003, size=(n, 2))
    return pg.relative_orientation(xy1, pg.project(g, io, e2), io)


def test_fit_repr_does_not_grow_with_the_number_of_points():
    # before: 16 639 characters for 30 points, 83 732 for 5000 (every id, every extra)
    small, large = repr(_relative(30)), repr(_relative(3000))
    assert large.startswith("RelativeOrientationFit(model=")
    assert len(large) < 3000 and abs(len(large) - len(small)) < 200
    assert re.search(r"ids=\('1', '2', '3', \.\.\. <\d+ items>\)", large)
    assert re.search(r"residuals=<array \(\d+, \d\) float64>", large)


def test_absolute_fit_repr_with_many_ids_is_short():
    rng = np.random.default_rng(1)
    x = rng.uniform(-5, 5, (20000, 3))
    fit = pg.absolute_orientation(x, x * 1.1 + 1.0, ids=[f"point-{i}" for i in range(20000)])
    text = repr(fit)
    assert len(text) < 3000 and "<20000 items>" in text and "sigma0=" in text


def test_bundle_fit_repr_is_short():
    # before: 86 660 characters for 8 images and 403 observations (snooping w, flagged list,
    # the private covariance arrays), growing with every flagged observation
    sim = pg.simulate.uav_block(
        "FC300S", seed=1, strips=2, images_per_strip=4, tie_points_per_image=40, blunders=20
    )
    fit = pg.bundle_adjust(sim.block)
    text = repr(fit)
    assert text.startswith("BundleFit(block=Block(1 cameras, 8 images")
    assert len(text) < 6000 and "_image_cov" not in text and "sigma0=" in text


@pytest.mark.parametrize(
    ("value", "shown"),
    [
        (np.arange(3.0), "array([0., 1., 2.])"),
        (np.zeros((40, 2)), "<array (40, 2) float64>"),
        (tuple(range(100)), "(0, 1, 2, ... <100 items>)"),
        ((5,), "(5,)"),
        ({i: i for i in range(50)}, "{0: 0, 1: 1, 2: 2, ... <50 entries>}"),
    ],
)
def test_compact_repr_of_each_kind_of_value(value, shown):
    from dataclasses import dataclass

    @dataclass(repr=False)
    class R:
        a: object
        _hidden: object = None

    assert compact_repr(R(value, np.zeros(10**4))) == f"R(a={shown})"
