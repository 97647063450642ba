"""Camera models keep arrays of their own: the caller's arrays are neither kept nor changed."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.rpc.model import RPC

sys.path.insert(0, str(Path(__file__).parent))
from rpc_samples import unit_rpc_tables


def test_rpc_copies_its_coefficients_and_correction():
    # before: line_num etc. were views of the caller's arrays while the stacked copy the
    # model computes with was not: after line_num[2] = 2.0 the RPC showed line_num[2] == 2
    # but still projected with 1; and the caller's correction array was made read-only
    line_num, den, samp_num = unit_rpc_tables()
    correction = np.zeros((2, 3))
    rpc = RPC(1000, 1000, 45, 7, 100, 1000, 1000, 0.1, 0.1, 500,
              line_num, den, samp_num, den, correction=correction)
    col, row = rpc.project(7.01, 45.01, 100.0)
    assert correction.flags.writeable and line_num.flags.writeable
    line_num[2] = 2.0
    correction[0, 2] = 5.0
    assert rpc.line_num[2] == 1.0 and rpc.correction[0, 2] == 0.0
    assert rpc.project(7.01, 45.01, 100.0) == (col, row)
    assert not rpc.line_num.flags.writeable and not rpc.correction.flags.writeable


def test_rpc_direct_model_copies_its_coefficients():
    from photogeom.rpc.model import DirectModel

    line_num, den, samp_num = unit_rpc_tables()
    d = DirectModel(line_num, den, samp_num, den)
    line_num[2] = 7.0
    assert d.lon_num[2] == 1.0


def _camera_data(n=12, seed=0):
    rng = np.random.default_rng(seed)
    g = np.column_stack([rng.uniform(-300, 300, (n, 2)), rng.uniform(0, 80, n)])
    io = pg.InteriorOrientation(100.0)
    eo = pg.ExteriorOrientation.from_degrees(10, 20, 800, 2, -3, 40)
    return g, pg.project(g, io, eo)


def test_dlt_keeps_parameters_of_its_own():
    # before: DLT(L) kept the caller's array: L[0] *= 2 afterwards changed the projection
    g, xy = _camera_data()
    L = np.array(pg.estimate_dlt(g, xy).model.L)
    dlt = pg.DLT(L)
    before = dlt.project(g)
    L[0] *= 2.0
    np.testing.assert_array_equal(dlt.project(g), before)
    assert L.flags.writeable and not dlt.L.flags.writeable
    P = dlt.matrix
    from_matrix = pg.DLT.from_matrix(P)
    P[0, 0] = 0.0
    np.testing.assert_array_equal(from_matrix.project(g), before)


def test_affine_camera_keeps_coefficients_of_its_own():
    g, xy = _camera_data()
    cam = pg.estimate_affine_camera(g, xy).model
    a, b = np.array(cam.a), np.array(cam.b)
    copy_cam = pg.AffineCamera(a, b)
    before = copy_cam.project(g)
    a[0] += 1.0
    b[3] += 5.0
    np.testing.assert_array_equal(copy_cam.project(g), before)
    assert not copy_cam.a.flags.writeable and not copy_cam.b.flags.writeable


def test_space_resection_batch_takes_a_list_of_start_orientations():
    # before: a list of ExteriorOrientation ended in "TypeError: float() argument must be ...
    # not 'ExteriorOrientation'", a start of the wrong shape in a numpy broadcast ValueError
    g, xy = _camera_data()
    io = pg.InteriorOrientation(100.0)
    eo = pg.ExteriorOrientation.from_degrees(10, 20, 800, 2, -3, 40)
    images = np.stack([xy] * 3)
    one = pg.space_resection_batch(g, images, io, eo)
    listed = pg.space_resection_batch(g, images, io, [eo] * 3)
    np.testing.assert_array_equal(listed.parameters, one.parameters)
    for bad, what in (
        (np.zeros((3, 5)), r"got shape \(3, 5\)"),
        (np.zeros((2, 6)), r"got shape \(2, 6\)"),
        ([eo, 1.0, eo], "mixing"),
    ):
        with pytest.raises(pg.InputError, match=r"initial: expected .*" + what):
            pg.space_resection_batch(g, images, io, bad)
