"""The observation-vectorised Metashape projection: against the camera model and by central
differences."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom import MetashapeCalibration, opk_from_matrix, opk_matrix
from photogeom.camera.frame_kernel import (
    increment_from_opk_jacobian,
    project_rows,
    rotation_increment,
)

CAL = MetashapeCalibration(
    4000,
    3000,
    3100.0,
    cx=12.5,
    cy=-8.0,
    k1=-0.05,
    k2=0.02,
    k3=-0.004,
    k4=0.0007,
    p1=3e-4,
    p2=-2e-4,
    b1=1.5,
    b2=-0.7,
)
CALV = np.array(
    [getattr(CAL, n) for n in ("f", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")]
)


def _rows(seed, n=40):
    rng = np.random.default_rng(seed)
    ang = rng.uniform(-0.3, 0.3, (n, 3)) + np.array([0.0, 0.0, rng.uniform(-3, 3)])
    M = opk_matrix(ang[:, 0], ang[:, 1], ang[:, 2])
    C = rng.uniform(-50, 50, (n, 3)) + np.array([0, 0, 120.0])
    # points in front: along the viewing direction (-z of the image system)
    cam = np.column_stack([rng.uniform(-0.5, 0.5, (n, 2)) * 100, -rng.uniform(80, 150, n)])
    X = C + np.einsum("nji,nj->ni", M, cam)
    cal = np.tile(CALV, (n, 1))
    size = np.tile([4000.0, 3000.0], (n, 1))
    return X, M, C, cal, size


def test_matches_the_camera_model():
    X, M, C, cal, size = _rows(0)
    pr = project_rows(X, M, C, cal, size, jacobian=False)
    p = np.einsum("nij,nj->ni", M, X - C)
    cam = np.column_stack([p[:, 0], -p[:, 1], -p[:, 2]])
    np.testing.assert_allclose(pr.uv, CAL.project_camera(cam), rtol=0, atol=1e-9)


@settings(max_examples=15, deadline=None, derandomize=True)
@given(st.integers(0, 10_000))
def test_derivatives_against_central_differences(seed):
    X, M, C, cal, size = _rows(seed, 10)
    pr = project_rows(X, M, C, cal, size)

    def num(fun, base, h):
        out = np.empty((X.shape[0], 2, base.shape[1]))
        for k in range(base.shape[1]):
            e = np.zeros_like(base)
            e[:, k] = h[k] if np.ndim(h) else h
            out[:, :, k] = (fun(base + e) - fun(base - e)) / (2 * e[:, k][:, None])
        return out

    uvX = lambda Xp: project_rows(Xp, M, C, cal, size, jacobian=False).uv  # noqa: E731
    np.testing.assert_allclose(pr.d_point, num(uvX, X, 1e-4), rtol=1e-6, atol=1e-6)
    uvC = lambda Cp: project_rows(X, M, Cp, cal, size, jacobian=False).uv  # noqa: E731
    np.testing.assert_allclose(pr.d_center, num(uvC, C, 1e-4), rtol=1e-6, atol=1e-6)

    def uvT(t):
        return project_rows(X, rotation_increment(t) @ M, C, cal, size, jacobian=False).uv

    np.testing.assert_allclose(
        pr.d_rotation, num(uvT, np.zeros((X.shape[0], 3)), 1e-7), rtol=1e-6, atol=1e-3
    )
    uvK = lambda k: project_rows(X, M, C, k, size, jacobian=False).uv  # noqa: E731
    h = np.array([1e-3, 1e-3, 1e-3, 1e-6, 1e-6, 1e-6, 1e-6, 1e-7, 1e-7, 1e-3, 1e-3])
    np.testing.assert_allclose(pr.d_calibration, num(uvK, cal, h), rtol=1e-6, atol=1e-5)


def test_increment_jacobian_against_differences_of_angles():
    rng = np.random.default_rng(3)
    ang = rng.uniform(-1.2, 1.2, (20, 3))
    T = increment_from_opk_jacobian(ang)
    M = opk_matrix(ang[:, 0], ang[:, 1], ang[:, 2])
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1e-6
        dtheta = T[:, :, k] * 1e-6
        Mp = rotation_increment(dtheta) @ M
        got = np.array([opk_from_matrix(m) for m in Mp])
        np.testing.assert_allclose((got - ang) / 1e-6, np.tile(np.eye(3)[k], (20, 1)), atol=1e-5)
