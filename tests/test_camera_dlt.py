"""DLT: spec example, conversions to and from orientations, estimation, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.camera.dlt_estimation import orthogonality_conditions
from photogeom.errors import DegenerateGeometryError, ReflectionError, TooFewPointsError

SPEC_L = [
    (0.0921, 4),
    (0.0164, 4),
    (-0.0043, 4),
    (-109.9007, 4),
    (-0.0162, 4),
    (0.0921, 4),
    (0.0041, 4),
    (-67.9431, 4),
    (-0.000032205, 9),
    (0.000021446, 9),
    (-0.00061413, 8),
]


def spec_camera():
    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    eo = pg.ExteriorOrientation.from_degrees(1114, 862, 1600, 2, 3, 10)
    return io, eo


def test_spec_dlt_parameters_to_printed_digits():
    L = pg.dlt_from_orientation(*spec_camera())
    assert L.shape == (11,)
    for value, (printed, digits) in zip(L, SPEC_L):
        assert round(value, digits) == pytest.approx(printed, abs=10 ** -(digits + 3))


def test_spec_dlt_against_textbook_formulas():
    # the formulas of 04-camera-models.md typed out, independent of the K M [I|-X0] route
    io, eo = spec_camera()
    M, (X0, Y0, Z0) = eo.matrix, eo.position
    x0, y0, c = io.x0, io.y0, io.f
    Q = -1 / (M[2] @ [X0, Y0, Z0])
    ref = [
        (x0 * M[2, 0] - c * M[0, 0]) * Q,
        (x0 * M[2, 1] - c * M[0, 1]) * Q,
        (x0 * M[2, 2] - c * M[0, 2]) * Q,
        x0 + (M[0] @ [X0, Y0, Z0]) * Q * c,
        (y0 * M[2, 0] - c * M[1, 0]) * Q,
        (y0 * M[2, 1] - c * M[1, 1]) * Q,
        (y0 * M[2, 2] - c * M[1, 2]) * Q,
        y0 + (M[1] @ [X0, Y0, Z0]) * Q * c,
        M[2, 0] * Q,
        M[2, 1] * Q,
        M[2, 2] * Q,
    ]
    np.testing.assert_allclose(pg.dlt_from_orientation(io, eo), ref, rtol=1e-13, atol=1e-15)


def test_textbook_back_formulas():
    L = pg.dlt_from_orientation(*spec_camera())
    L2 = L[8] ** 2 + L[9] ** 2 + L[10] ** 2
    x0 = (L[0] * L[8] + L[1] * L[9] + L[2] * L[10]) / L2
    y0 = (L[4] * L[8] + L[5] * L[9] + L[6] * L[10]) / L2
    cx = np.sqrt((L[0] ** 2 + L[1] ** 2 + L[2] ** 2) / L2 - x0**2)
    io, eo = pg.orientation_from_dlt(L)
    assert io.x0 == pytest.approx(x0, abs=1e-12) and io.y0 == pytest.approx(y0, abs=1e-12)
    assert io.fx == pytest.approx(cx, rel=1e-12)
    A = np.array([L[0:3], L[4:7], L[8:11]])
    np.testing.assert_allclose(eo.position, -np.linalg.solve(A, [L[3], L[7], 1.0]), rtol=1e-12)
    assert np.abs(orthogonality_conditions(L)).max() < 1e-12


def test_camera_matrix_and_dlt_object():
    io, eo = spec_camera()
    dlt = pg.DLT(pg.dlt_from_orientation(io, eo))
    P = pg.camera_matrix(io, eo)
    np.testing.assert_allclose(P / P[2, 3], dlt.matrix, rtol=1e-13)
    np.testing.assert_allclose(pg.DLT.from_matrix(5 * P).L, dlt.L, rtol=1e-13)
    np.testing.assert_allclose(dlt.projection_centre, eo.position, rtol=1e-12)
    assert pg.DLT.from_dict(dlt.to_dict()).L.tolist() == dlt.L.tolist()


camera_angles = st.tuples(
    st.floats(-np.pi, np.pi), st.floats(-1.55, 1.55), st.floats(-np.pi, np.pi)
)


@settings(max_examples=150, deadline=None)
@given(
    angles=camera_angles,
    pos=st.tuples(*[st.floats(-2000, 2000)] * 3),
    f=st.floats(20, 8000),
    pp=st.tuples(st.floats(-0.03, 0.03), st.floats(-0.03, 0.03)),
    b=st.tuples(st.floats(-0.02, 0.02), st.floats(-0.002, 0.002)),
    nadir=st.booleans(),
)
def test_round_trip_orientation_dlt_orientation(angles, pos, f, pp, b, nadir):
    if nadir:  # aerial nadir images: small omega/phi, any kappa, camera above the origin
        angles = (angles[0] * 0.02, angles[1] * 0.02, angles[2])
        pos = (pos[0], pos[1], abs(pos[2]) + 500.0)
    io = pg.InteriorOrientation(f, pp[0] * f, pp[1] * f, unit="px", b1=b[0] * f, b2=b[1] * f)
    eo = pg.ExteriorOrientation(*pos, *angles)
    M = eo.matrix
    # the DLT normalisation L12 = 1 needs the origin away from the camera's principal plane
    assume(np.linalg.norm(eo.position) > 1.0)
    assume(abs(M[2] @ eo.position) > 0.05 * np.linalg.norm(eo.position))
    io2, eo2 = pg.orientation_from_dlt(pg.dlt_from_orientation(io, eo), unit="px")
    for name in ("f", "x0", "y0", "b1", "b2"):
        assert abs(getattr(io2, name) - getattr(io, name)) <= 1e-10 * f, name
    np.testing.assert_allclose(eo2.position, eo.position, rtol=0, atol=1e-10)
    np.testing.assert_allclose(eo2.matrix, M, rtol=0, atol=1e-12)
    if np.cos(eo.phi) > 1e-3:  # angles are unique away from gimbal lock
        d = np.angle(np.exp(1j * (eo2.angles - eo.angles)))
        np.testing.assert_allclose(d, 0, atol=1e-10)


@settings(max_examples=40, deadline=None)
@given(angles=camera_angles, seed=st.integers(0, 2**31 - 1))
def test_dlt_and_collinearity_project_alike(angles, seed):
    rng = np.random.default_rng(seed)
    io = pg.InteriorOrientation(150.0, 0.02, -0.01, b1=0.3, b2=-0.05)
    eo = pg.ExteriorOrientation(*rng.uniform(-500, 500, 3), *angles)
    assume(np.linalg.norm(eo.position) > 1.0)
    assume(abs(eo.matrix[2] @ eo.position) > 0.05 * np.linalg.norm(eo.position))
    xn = rng.uniform(-0.5, 0.5, (100, 2))
    depth = rng.uniform(5, 1000, 100)
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(100)]) * depth[:, None]
    g = eo.position + pc @ eo.matrix
    dlt = pg.DLT(pg.dlt_from_orientation(io, eo))
    np.testing.assert_allclose(dlt.project(g), pg.project(g, io, eo), rtol=0, atol=1e-8)


def _control(n, rng, io, eo, depth=(800, 1600)):
    xn = rng.uniform(-0.6, 0.6, (n, 2))
    d = rng.uniform(*depth, n)
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(n)]) * d[:, None]
    g = eo.position + pc @ eo.matrix
    return g, pg.project(g, io, eo)


def test_estimation_recovers_noise_free_parameters():
    rng = np.random.default_rng(1)
    io, eo = spec_camera()
    L = pg.dlt_from_orientation(io, eo)
    g, xy = _control(12, rng, io, eo)
    for kw in ({"refine": False}, {}, {"constrained": True}):
        fit = pg.estimate_dlt(g, xy, **kw)
        np.testing.assert_allclose(fit.parameters, L, rtol=1e-9, atol=1e-12)
        assert fit.rmse < 1e-9
        assert fit.redundancy == 24 - 11 + (2 if kw.get("constrained") else 0)
        np.testing.assert_allclose(fit.exterior.position, eo.position, rtol=1e-9)
        assert fit.interior.f == pytest.approx(152.14, rel=1e-9)


def test_constrained_dlt_from_five_points():
    rng = np.random.default_rng(7)
    io, eo = spec_camera()
    g, xy = _control(5, rng, io, eo)
    fit = pg.estimate_dlt(g, xy, constrained=True)
    assert fit.redundancy == 1
    np.testing.assert_allclose(fit.parameters, pg.dlt_from_orientation(io, eo), rtol=1e-8)
    with pytest.raises(TooFewPointsError, match="at least 6"):
        pg.estimate_dlt(g, xy)


def test_constrained_dlt_equals_self_calibrating_resection():
    # Independent method: the constrained DLT is the collinearity model with f, x0, y0 free;
    # both adjustments minimise the same image residuals, so their estimates coincide.
    rng = np.random.default_rng(11)
    io, eo = spec_camera()
    g, xy = _control(15, rng, io, eo, depth=(600, 2500))
    xy = xy + rng.normal(0, 0.004, xy.shape)
    fit_dlt = pg.estimate_dlt(g, xy, constrained=True)
    fit_res = pg.space_resection(g, xy, io, calibrate=("f", "x0", "y0"))
    np.testing.assert_allclose(fit_dlt.residuals, fit_res.residuals, atol=1e-9)
    assert fit_dlt.sigma0 == pytest.approx(fit_res.sigma0, rel=1e-7)
    np.testing.assert_allclose(fit_dlt.exterior.position, fit_res.exterior.position, rtol=1e-8)
    assert fit_dlt.interior.f == pytest.approx(fit_res.interior.f, rel=1e-8)


def test_dlt_noise_statistics():
    rng = np.random.default_rng(2)
    io, eo = spec_camera()
    g, xy = _control(30, rng, io, eo)
    obs = xy + rng.normal(0, 0.005, xy.shape)
    fit = pg.estimate_dlt(g, obs, sigma=0.005)
    assert 0.7 < fit.sigma0 < 1.3
    assert fit.residuals.shape == (30, 2) and fit.residual_unit == "mm"
    # residuals are computed minus observed image coordinates
    np.testing.assert_allclose(fit.residuals, fit.dlt.project(g) - obs, atol=1e-10)
    gc, xyc = _control(4, rng, io, eo)
    fit = pg.estimate_dlt(g, xy, check_ground=gc, check_image=xyc, check_ids=list("abcd"))
    assert fit.check_residuals.shape == (4, 2) and fit.check_rmse < 1e-8


def test_coplanar_control_is_refused_with_advice():
    rng = np.random.default_rng(3)
    io, eo = spec_camera()
    g = np.column_stack(
        [rng.uniform(900, 1400, 10), rng.uniform(500, 1000, 10), np.full(10, 200.0)]
    )
    xy = pg.project(g, io, eo)
    for kw in ({}, {"constrained": True}):
        with pytest.raises(DegenerateGeometryError, match="coplanar") as exc:
            pg.estimate_dlt(g, xy, **kw)
        assert "space resection" in str(exc.value) and "constrained DLT" in str(exc.value)


def test_left_handed_image_coordinates_are_detected():
    rng = np.random.default_rng(4)
    io, eo = spec_camera()
    g, xy = _control(10, rng, io, eo)
    mirrored = xy * [1.0, -1.0]  # e.g. pixel rows used as y
    with pytest.raises(ReflectionError, match="left-handed"):
        pg.estimate_dlt(g, mirrored)


def test_decomposed_orientation_std_against_monte_carlo():
    """The standard deviations of the orientation decomposed from the DLT (propagated from
    the DLT's covariance) against the spread of the decomposition over redrawn image noise:
    300 trials, each ratio within 15 % (the spread of a standard deviation from 300 draws
    is about 4 %; the decomposition is non-linear)."""
    rng = np.random.default_rng(12)
    io, eo = spec_camera()
    g, xy = _control(20, rng, io, eo)
    sigma = 0.005
    reported = pg.estimate_dlt(g, xy + rng.normal(0, sigma, xy.shape), sigma=sigma)
    prior = reported.orientation_std("rad", prior=True)
    vals = []
    for _ in range(300):
        fit = pg.estimate_dlt(g, xy + rng.normal(0, sigma, xy.shape), sigma=sigma)
        i, e = fit.interior, fit.exterior
        vals.append([i.fx, i.fy, i.x0, i.y0, i.b2, e.X0, e.Y0, e.Z0, e.omega, e.phi, e.kappa])
    spread = np.std(np.array(vals), axis=0, ddof=1)
    from photogeom.camera.dlt_estimation import ORIENTATION_NAMES

    ratio = spread / np.array([prior[n] for n in ORIENTATION_NAMES])
    assert np.all((ratio > 0.85) & (ratio < 1.15)), dict(zip(ORIENTATION_NAMES, ratio))
    # a posteriori = a priori scaled by sigma0; angles converted to the unit asked for
    post = reported.orientation_std("gon")
    assert post["X0"] == pytest.approx(prior["X0"] * reported.sigma0, rel=1e-6)
    assert post["kappa"] == pytest.approx(prior["kappa"] * reported.sigma0 * 200 / np.pi, rel=1e-6)
