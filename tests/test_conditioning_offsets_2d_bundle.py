"""2D transformations and the bundle adjustment do not depend on where the coordinates are.

The same problem is solved at the origin and translated by random UTM-sized and geocentric
offsets; after undoing the translation, estimates, sigma0, residuals and standard deviations
must agree to the representation floor of the shifted coordinates (2.2e-16 x 6.4e6 m =
1.4e-9 m), which puts sigma0 of residuals of ~0.01 within ~1e-7 relative.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg

OFFSETS_2D = st.tuples(
    st.floats(-7e6, 7e6, allow_nan=False), st.floats(-7e6, 7e6, allow_nan=False)
).map(np.array)


def _rel(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) / np.asarray(b) - 1.0)))


@settings(max_examples=20, deadline=None)
@given(shift=OFFSETS_2D, shift_to=OFFSETS_2D)
@pytest.mark.parametrize("model", ["similarity2d", "affine2d", "polynomial2d", "projective2d"])
def test_2d_transformations_do_not_depend_on_the_offsets(model, shift, shift_to):
    rng = np.random.default_rng(4)
    src = rng.uniform(-500, 500, (30, 2))
    if model == "projective2d":
        h = np.c_[src, np.ones(30)] @ np.array([[1, 0.01, 5], [0.02, 1, 3], [1e-6, 2e-6, 1]]).T
        dst = h[:, :2] / h[:, 2:]
    else:
        dst = src @ np.array([[1.0001, 0.02], [-0.019, 0.9999]]).T + [10.0, 20.0]
    dst = dst + rng.normal(0.0, 0.01, src.shape)
    order = 2 if model == "polynomial2d" else None
    f0 = pg.estimate_transform(model, src, dst, order=order)
    f1 = pg.estimate_transform(model, src + shift, dst + shift_to, order=order)
    assert abs(f1.sigma0 / f0.sigma0 - 1.0) < 1e-7
    assert np.max(np.abs(f1.residuals - f0.residuals)) < 1e-8
    assert np.max(np.abs(f1.transform(src + shift) - shift_to - f0.transform(src))) < 1e-7
    assert np.max(np.abs(f1.redundancy_numbers - f0.redundancy_numbers)) < 1e-6
    if model in ("similarity2d", "affine2d"):
        # the linear part's parameters do not change with a translation, nor their std
        lin = ["a", "b"] if model == "similarity2d" else ["a1", "a2", "b1", "b2"]
        s0, s1 = f0.std_errors, f1.std_errors
        assert _rel([s1[n] for n in lin], [s0[n] for n in lin]) < 1e-6


def _shifted(block: pg.bundle.Block, s: np.ndarray) -> pg.bundle.Block:
    ex = np.array(block.exterior, dtype=float)
    ex[:, :3] += s
    return block.replace(
        exterior=ex, gnss=np.asarray(block.gnss) + s, xyz=np.asarray(block.xyz) + s
    )


@pytest.fixture(scope="module")
def uav():
    sim = pg.simulate.uav_block("FC300S", seed=3, strips=2, images_per_strip=5,
                                local_field=0.0)  # fmt: skip
    return sim.block, pg.bundle_adjust(sim.block, point_covariance=True)


@settings(max_examples=4, deadline=None)
@given(shift=st.sampled_from([(500000.0, 5000000.0, 300.0), (4.2e6, 1.1e6, 4.7e6)]).map(
    np.array
) | st.tuples(*[st.floats(-6.4e6, 6.4e6, allow_nan=False)] * 3).map(np.array))
def test_bundle_with_gnss_control_and_checks_does_not_depend_on_the_offset(uav, shift):
    block, f0 = uav
    f1 = pg.bundle_adjust(_shifted(block, shift), point_covariance=True)
    assert abs(f1.sigma0 / f0.sigma0 - 1.0) < 1e-8
    e0, e1 = np.asarray(f0.block.exterior), np.asarray(f1.block.exterior)
    assert np.max(np.abs(e1[:, :3] - shift - e0[:, :3])) < 1e-7
    assert np.max(np.abs(e1[:, 3:] - e0[:, 3:])) < 1e-9
    assert np.max(np.abs(np.asarray(f1.block.xyz) - shift - np.asarray(f0.block.xyz))) < 1e-7
    assert _rel(f1.exterior_std, f0.exterior_std) < 1e-7
    assert _rel(f1.point_std, f0.point_std) < 1e-7
    assert np.max(np.abs(f1.check["errors"] - f0.check["errors"])) < 1e-7
    assert np.max(np.abs(f1.residuals - f0.residuals)) < 1e-6  # px
