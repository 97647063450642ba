"""8-parameter affine camera and interior orientation from fiducial marks."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import DegenerateGeometryError, TooFewPointsError

A = (0.3, -0.2, 0.0004, 8060.0)
B = (-0.29, 0.18, 0.0005, 9600.0)


def test_spec_affine_camera_example():
    cam = pg.AffineCamera(A, B)
    x, y = cam.project([1300.0, 650.0, 169.0])
    assert round(x, 4) == 8320.0676
    assert round(y, 4) == 9340.0845
    assert pg.AffineCamera.from_dict(cam.to_dict()).parameters.tolist() == [*A, *B]


def _ground(n, rng, utm=False):
    g = np.column_stack(
        [rng.uniform(0, 2000, n), rng.uniform(0, 2000, n), rng.uniform(100, 400, n)]
    )
    return g + ([500000.0, 4000000.0, 0.0] if utm else 0.0)


@pytest.mark.parametrize("utm", [False, True])
def test_estimation_recovers_parameters(utm):
    rng = np.random.default_rng(0)
    g = _ground(4, rng, utm)
    true = pg.AffineCamera(A, B)
    if utm:  # same image geometry, coordinates far from the origin (conditioning)
        shift = np.array([500000.0, 4000000.0, 0.0])
        a4 = A[3] - np.dot(A[:3], shift)
        b4 = B[3] - np.dot(B[:3], shift)
        true = pg.AffineCamera((*A[:3], a4), (*B[:3], b4))
    xy = true.project(g)
    fit = pg.estimate_affine_camera(g, xy)
    assert fit.redundancy == 0 and np.isnan(fit.sigma0)
    np.testing.assert_allclose(fit.parameters, true.parameters, rtol=1e-9, atol=1e-9)


def test_estimation_statistics_against_numpy_lstsq():
    rng = np.random.default_rng(1)
    g = _ground(25, rng)
    xy = pg.AffineCamera(A, B).project(g) + rng.normal(0, 0.5, (25, 2))
    fit = pg.estimate_affine_camera(g, xy, sigma=0.5, ids=range(25))
    # independent solution: ordinary least squares per image axis on raw coordinates
    D = np.column_stack([g, np.ones(25)])
    ax = np.linalg.lstsq(D, xy[:, 0], rcond=None)[0]
    by = np.linalg.lstsq(D, xy[:, 1], rcond=None)[0]
    np.testing.assert_allclose(fit.parameters, np.concatenate([ax, by]), rtol=1e-8, atol=1e-8)
    Q = np.linalg.inv(D.T @ D) * 0.25  # sigma = 0.5 => P = 4
    np.testing.assert_allclose(fit.cofactor[:4, :4], Q, rtol=1e-6)
    np.testing.assert_allclose(fit.residuals, fit.model.project(g) - xy, atol=1e-9)
    assert fit.redundancy == 50 - 8 and 0.6 < fit.sigma0 < 1.4


def test_affine_camera_bad_geometry():
    rng = np.random.default_rng(2)
    g = _ground(10, rng)
    xy = pg.AffineCamera(A, B).project(g)
    flat = g.copy()
    flat[:, 2] = 169.0
    with pytest.raises(DegenerateGeometryError, match="one height"):
        pg.estimate_affine_camera(flat, xy)
    tilted = g.copy()
    tilted[:, 2] = 0.1 * g[:, 0]  # a tilted plane
    with pytest.raises(DegenerateGeometryError, match="coplanar"):
        pg.estimate_affine_camera(tilted, xy)
    with pytest.raises(TooFewPointsError, match="at least 4"):
        pg.estimate_affine_camera(g[:3], xy[:3])


CAL = np.array(
    [
        [-106.0, -106.0],
        [106.0, 106.0],
        [-106.0, 106.0],
        [106.0, -106.0],
        [0.0, -110.0],
        [0.0, 110.0],
        [-110.0, 0.0],
        [110.0, 0.0],
    ]
)


def test_fiducial_marks_comparator_and_pixel():
    ang = 0.012
    R = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    meas = CAL @ R.T * np.array([1.0003, 0.9998]) + [120.3, 98.2]  # comparator, affine film
    fit = pg.fit_fiducials(meas, CAL, model="affine", check=[0, 0, 0, 0, 0, 0, 1, 1])
    assert fit.check_residuals.shape == (2, 2)
    assert np.max(np.abs(fit.residuals)) < 1e-9 and np.max(np.abs(fit.check_residuals)) < 1e-9
    # scanned film in pixels (rows down): the row sign is handled, no reflection is fitted
    pix = np.column_stack([meas[:, 0] / 0.02 + 100, -meas[:, 1] / 0.02 + 12000])
    fitp = pg.fit_fiducials(pix, CAL, model="projective", measured_system="pixel")
    np.testing.assert_allclose(pg.camera.measured_to_fiducial(fitp, pix), CAL, atol=1e-7)
    assert any("left-handed" in note for note in fitp.notes)
    sim = pg.fit_fiducials(meas, CAL, model="similarity")
    assert sim.rmse > 0.001  # the affine film deformation shows in the similarity residuals
    with pytest.raises(pg.InputError, match="fiducial model"):
        pg.fit_fiducials(meas, CAL, model="helmert")
