"""Rotation conventions of 01-conventions.md section 2, against closed formulas and scipy."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import polar
from scipy.spatial.transform import Rotation

import photogeom as pg
from photogeom import rotation as rot
from photogeom.errors import GimbalLockError, InputError

angle = st.floats(-np.pi, np.pi, allow_nan=False)
phi_ok = st.floats(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, allow_nan=False)


def test_lecture_example_8_matrix():
    M = pg.opk_matrix(*np.radians([10.0, 15.0, 50.0]))
    expected = [
        [0.620885, 0.7832956, -0.030816],
        [-0.739942, 0.5985935, 0.306874],
        [0.258819, -0.1677312, 0.951251],
    ]
    np.testing.assert_allclose(M, expected, atol=5e-7)


def test_lecture_example_8_similarity_transposed():
    M = pg.opk_matrix(*np.radians([10.0, 15.0, 50.0]))
    X = M.T @ np.array([1354.0, 547.0, 135.0]) + np.array([-200.0, 136.0, 189.0])
    np.testing.assert_allclose(X, [270.8707, 1501.3692, 443.5540], atol=5e-5)
    R = pg.rotation_from_angles(10, 15, 50, convention="transposed", unit="deg")
    np.testing.assert_allclose(R, M.T, atol=1e-15)


@given(angle, angle, angle)
@settings(max_examples=60, deadline=None)
def test_opk_matrix_is_product_of_elementary_axis_rotations(w, p, k):
    M = pg.opk_matrix(w, p, k)
    np.testing.assert_allclose(M, rot.m3(k) @ rot.m2(p) @ rot.m1(w), atol=1e-14)
    assert pg.orthogonality_defect(M) < 1e-14
    assert np.linalg.det(M) == pytest.approx(1.0)


@given(angle)
@settings(max_examples=30, deadline=None)
def test_elementary_rotations_are_passive(t):
    # Mi(t) = Ri(-t), Ri the active rotation about axis i (scipy's matrices are active)
    for Mi, ax in ((rot.m1, "x"), (rot.m2, "y"), (rot.m3, "z")):
        np.testing.assert_allclose(Mi(t), Rotation.from_euler(ax, -t).as_matrix(), atol=1e-14)


def test_elementary_rotation_sign_by_hand():
    # Rotating the axes by +90 deg about z: the old x axis appears at -90 deg in the new
    # system, i.e. point (1, 0, 0) has new coordinates (0, -1, 0).
    np.testing.assert_allclose(rot.m3(np.pi / 2) @ [1, 0, 0], [0, -1, 0], atol=1e-15)
    np.testing.assert_allclose(rot.m1(np.pi / 2) @ [0, 1, 0], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(rot.m2(np.pi / 2) @ [0, 0, 1], [-1, 0, 0], atol=1e-15)


@given(angle, phi_ok, angle)
@settings(max_examples=100, deadline=None)
def test_opk_round_trip(w, p, k):
    w2, p2, k2 = pg.opk_from_matrix(pg.opk_matrix(w, p, k))
    np.testing.assert_allclose(pg.opk_matrix(w2, p2, k2), pg.opk_matrix(w, p, k), atol=1e-12)
    assert p2 == pytest.approx(p, abs=1e-9)
    assert np.cos(w2 - w) == pytest.approx(1.0, abs=1e-12)
    assert np.cos(k2 - k) == pytest.approx(1.0, abs=1e-12)


def test_opk_from_matrix_published_formulas():
    M = pg.opk_matrix(0.3, -0.4, 2.5)
    w, p, k = pg.opk_from_matrix(M)
    assert p == pytest.approx(np.arcsin(M[2, 0]))
    assert w == pytest.approx(np.arctan2(-M[2, 1], M[2, 2]))
    assert k == pytest.approx(np.arctan2(-M[1, 0], M[0, 0]))


def test_batched_matrices_and_angles():
    rng = np.random.default_rng(3)
    w, k = rng.uniform(-np.pi, np.pi, (2, 50))
    p = rng.uniform(-1.5, 1.5, 50)
    M = pg.opk_matrix(w, p, k)
    assert M.shape == (50, 3, 3)
    w2, p2, k2 = pg.opk_from_matrix(M)
    np.testing.assert_allclose(np.stack([w2, p2, k2]), np.stack([w, p, k]), atol=1e-12)


def test_gimbal_lock_is_reported():
    M = pg.opk_matrix(0.2, np.pi / 2, 0.5)
    with pytest.raises(GimbalLockError, match="gimbal lock"):
        pg.opk_from_matrix(M)
    w, p, k = pg.opk_from_matrix(M, on_gimbal_lock="omega-zero")
    assert w == 0.0 and p == pytest.approx(np.pi / 2)
    np.testing.assert_allclose(pg.opk_matrix(w, p, k), M, atol=1e-12)
    M2 = pg.opk_matrix(-0.7, -np.pi / 2, 0.1)
    np.testing.assert_allclose(
        pg.opk_matrix(*pg.opk_from_matrix(M2, on_gimbal_lock="omega-zero")), M2, atol=1e-12
    )


@given(angle, phi_ok, angle)
@settings(max_examples=50, deadline=None)
def test_similarity_conventions(w, p, k):
    Rt = pg.rotation_from_angles(w, p, k, convention="transposed")
    Rd = pg.rotation_from_angles(w, p, k, convention="direct")
    np.testing.assert_allclose(Rd, pg.opk_matrix(w, p, k), atol=1e-15)
    # transposed = R1(w) R2(p) R3(k) with active elementary rotations
    active = (
        Rotation.from_euler("x", w).as_matrix()
        @ Rotation.from_euler("y", p).as_matrix()
        @ Rotation.from_euler("z", k).as_matrix()
    )
    np.testing.assert_allclose(Rt, active, atol=1e-14)
    for conv, R in (("transposed", Rt), ("direct", Rd)):
        back = pg.angles_from_rotation(R, convention=conv)
        np.testing.assert_allclose(pg.rotation_from_angles(*back, convention=conv), R, atol=1e-12)


def test_angle_units_in_conversions():
    R = pg.rotation_from_angles(50, 60, 130, convention="direct", unit="deg")
    np.testing.assert_allclose(pg.angles_from_rotation(R, "direct", "deg"), [50, 60, 130])
    np.testing.assert_allclose(
        pg.angles_from_rotation(R, "direct", "gon"), np.array([50, 60, 130]) * 400 / 360
    )
    with pytest.raises(InputError, match="convention"):
        pg.rotation_from_angles(0, 0, 0, convention="sideways")
    with pytest.raises(InputError, match="unknown angle unit"):
        pg.rotation_from_angles(0, 0, 0, unit="furlong")


def test_quaternion_order_and_sign():
    R = Rotation.from_euler("z", 90, degrees=True).as_matrix()  # x -> y
    q = pg.quaternion_from_matrix(R, scalar_first=True)
    np.testing.assert_allclose(q, [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], atol=1e-15)
    np.testing.assert_allclose(pg.quaternion_from_matrix(R, scalar_first=False), np.roll(q, -1))
    np.testing.assert_allclose(pg.matrix_from_quaternion(-2 * q), R, atol=1e-15)
    with pytest.raises(InputError, match="zero quaternion"):
        pg.matrix_from_quaternion([0, 0, 0, 0])


@given(angle, phi_ok, angle)
@settings(max_examples=40, deadline=None)
def test_other_parametrisations_round_trip(w, p, k):
    R = pg.rotation_from_angles(w, p, k)
    np.testing.assert_allclose(
        pg.matrix_from_quaternion(pg.quaternion_from_matrix(R)), R, atol=1e-12
    )
    axis, ang = pg.axis_angle_from_matrix(R)
    np.testing.assert_allclose(pg.matrix_from_axis_angle(axis, ang), R, atol=1e-12)
    if ang < np.pi - 1e-3:
        g = pg.rodrigues_from_matrix(R)
        np.testing.assert_allclose(pg.matrix_from_rodrigues(g), R, atol=1e-10)
        np.testing.assert_allclose(g, np.tan(ang / 2) * axis, atol=1e-12)
    e = pg.euler_from_matrix(R, "ZYX")
    np.testing.assert_allclose(pg.matrix_from_euler("ZYX", e), R, atol=1e-12)


def test_rodrigues_matrix_formula_matches_scipy():
    g = np.array([0.3, -0.2, 0.5])
    ang = 2 * np.arctan(np.linalg.norm(g))
    expected = Rotation.from_rotvec(g / np.linalg.norm(g) * ang).as_matrix()
    np.testing.assert_allclose(pg.matrix_from_rodrigues(g), expected, atol=1e-14)


def test_nearest_rotation_is_polar_factor():
    rng = np.random.default_rng(0)
    R = pg.rotation_from_angles(0.4, -0.2, 2.0)
    A = R + 1e-3 * rng.normal(size=(3, 3))
    U, _ = polar(A)  # independent: scipy's polar decomposition
    np.testing.assert_allclose(pg.nearest_rotation(A), U, atol=1e-12)
    # reflection input gives a proper rotation
    F = np.diag([1.0, 1.0, -1.0]) @ R
    assert np.linalg.det(pg.nearest_rotation(F)) == pytest.approx(1.0)


def test_skew_matches_cross_product():
    a, b = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.7, -1.1])
    np.testing.assert_allclose(rot.skew(a) @ b, np.cross(a, b), atol=1e-15)


def test_bad_shapes():
    with pytest.raises(InputError, match="3, 3"):
        pg.opk_from_matrix(np.eye(2))


def test_units_helpers():
    assert pg.deg2gon(90) == pytest.approx(100)
    assert pg.gon2deg(400) == pytest.approx(360)
    assert pg.to_radians(200, "gon") == pytest.approx(np.pi)
    assert pg.from_radians(np.pi, "arcsec") == pytest.approx(648000)


@given(angle, phi_ok, angle)
@settings(max_examples=40, deadline=None)
def test_scalar_matrix_and_derivatives_match_central_differences(w, p, k):
    M, dM = rot.opk_matrix_and_derivatives(w, p, k)
    np.testing.assert_allclose(M, pg.opk_matrix(w, p, k), atol=1e-15)
    h = 1e-6
    for j, d in enumerate(dM):
        a = np.array([w, p, k])
        b = a.copy()
        a[j] += h
        b[j] -= h
        np.testing.assert_allclose(d, (pg.opk_matrix(*a) - pg.opk_matrix(*b)) / (2 * h), atol=1e-8)
