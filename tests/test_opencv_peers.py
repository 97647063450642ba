"""Least-squares minima against OpenCV on the same noisy data: space resection against
``cv2.solvePnP`` (iterative, reprojection error in pixels), the 2D projective transformation
against ``cv2.findHomography`` (all points, Levenberg-Marquardt refinement of the target
error), the 2D affine and similarity transformations against ``cv2.estimateAffine2D`` /
``cv2.estimateAffinePartial2D`` (every point an inlier, refined by Levenberg-Marquardt).

OpenCV stops its refinements at its own tolerances, so the agreement is to those (about
1e-6 relative); photogeom's sum of squares is never larger.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import photogeom as pg

FLIP = np.diag([1.0, -1.0, -1.0])  # photogrammetric camera (y up, looks along -z) <-> OpenCV


@pytest.mark.parametrize(
    "angles", [(10.0, -20.0, 170.0), (179.0, 5.0, -179.0), (-30.0, 80.0, 20.0), (0.0, 0.0, 0.0)]
)
def test_space_resection_is_opencvs_solvepnp(angles):
    rng = np.random.default_rng(5)
    io = pg.InteriorOrientation.digital(3000.0, 2000.0, 1500.0, image_size=(4000, 3000))
    eo = pg.ExteriorOrientation(5.0, -3.0, 20.0, *np.radians(angles))
    n = 15
    xn = rng.uniform(-0.6, 0.6, (n, 2))
    depth = rng.uniform(5.0, 15.0, n)
    rays = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(n)]) * depth[:, None]
    g = eo.position + rays @ eo.matrix
    cr = io.image_to_pixel(pg.project(g, io, eo)) + rng.normal(0.0, 0.5, (n, 2))
    fit = pg.space_resection(g, cr, io, system="pixel")

    K = np.array([[3000.0, 0.0, 2000.0], [0.0, 3000.0, 1500.0], [0.0, 0.0, 1.0]])
    R0 = FLIP @ eo.matrix
    ok, rvec, tvec = cv2.solvePnP(
        g, cr, K, None, cv2.Rodrigues(R0)[0], -R0 @ eo.position, useExtrinsicGuess=True,
        flags=cv2.SOLVEPNP_ITERATIVE,
    )
    assert ok
    R = cv2.Rodrigues(rvec)[0]
    np.testing.assert_allclose(fit.exterior.position, -R.T @ tvec.ravel(), atol=1e-5)
    np.testing.assert_allclose(fit.exterior.matrix, FLIP @ R, atol=1e-7)
    # the same minimum: OpenCV's reprojection errors are those of the fit (pixels)
    cv_px = cv2.projectPoints(g, rvec, tvec, K, None)[0].reshape(-1, 2)
    fit_px = io.image_to_pixel(pg.project(g, io, fit.exterior))
    assert np.sum((fit_px - cr) ** 2) <= np.sum((cv_px - cr) ** 2) * (1 + 1e-9)
    np.testing.assert_allclose(fit_px, cv_px, atol=1e-4)


def _points(rng, n=30):
    return rng.uniform(0.0, 1000.0, (n, 2))


def test_projective2d_is_opencvs_homography():
    rng = np.random.default_rng(5)
    H = np.array([[1.1, 0.05, 3.0], [0.02, 0.97, -2.0], [1e-4, 2e-4, 1.0]])
    src = _points(rng)
    h = np.c_[src, np.ones(len(src))] @ H.T
    dst = h[:, :2] / h[:, 2:] + rng.normal(0.0, 0.5, src.shape)
    fit = pg.estimate_transform("projective2d", src, dst)
    Hcv, _ = cv2.findHomography(src, dst, 0)
    ours = np.r_[fit.parameters, 1.0].reshape(3, 3)
    np.testing.assert_allclose(ours, Hcv / Hcv[2, 2], rtol=0, atol=5e-5 * np.abs(ours).max())
    hc = np.c_[src, np.ones(len(src))] @ Hcv.T
    ssr_cv = np.sum((hc[:, :2] / hc[:, 2:] - dst) ** 2)
    assert np.sum(fit.residuals**2) <= ssr_cv * (1 + 1e-9)
    assert np.sum(fit.residuals**2) == pytest.approx(ssr_cv, rel=1e-6)


def test_affine2d_is_opencvs_estimate_affine_2d():
    rng = np.random.default_rng(6)
    src = _points(rng)
    A = np.array([[0.9, 0.2, 30.0], [-0.1, 1.2, -40.0]])
    dst = src @ A[:, :2].T + A[:, 2] + rng.normal(0.0, 0.5, src.shape)
    fit = pg.estimate_transform("affine2d", src, dst)
    Acv, inliers = cv2.estimateAffine2D(
        src, dst, method=cv2.RANSAC, ransacReprojThreshold=1e6, refineIters=100
    )
    assert inliers.all()
    np.testing.assert_allclose(fit.parameters, Acv.ravel(), rtol=1e-6, atol=1e-5)


def test_similarity2d_is_opencvs_estimate_affine_partial_2d():
    rng = np.random.default_rng(7)
    src = _points(rng)
    true = pg.Similarity2D.from_textbook(1.2, np.radians(170.0), 30.0, -40.0)
    dst = true.apply(src) + rng.normal(0.0, 0.5, src.shape)
    fit = pg.estimate_transform("similarity2d", src, dst)
    Scv, inliers = cv2.estimateAffinePartial2D(
        src, dst, method=cv2.RANSAC, ransacReprojThreshold=1e6, refineIters=100
    )
    assert inliers.all()
    np.testing.assert_allclose(fit.model.apply(src), src @ Scv[:, :2].T + Scv[:, 2], atol=1e-4)
    scale, theta = fit.extras["textbook"]["scale"][0], fit.extras["textbook"]["theta"][0]
    assert scale == pytest.approx(np.hypot(*Scv[:, 0]), rel=1e-7)
    assert np.cos(theta - np.arctan2(Scv[1, 0], Scv[0, 0])) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("angles", [(2.0, 3.0, 10.0), (179.5, 10.0, -179.5), (30.0, -60.0, 170.0)])
def test_dlt_decomposition_is_opencvs_decompose_projection_matrix(angles):
    """The interior and exterior orientation decomposed from an estimated DLT against
    ``cv2.decomposeProjectionMatrix`` of the same 3x4 matrix (image y up -> OpenCV's rows
    down; OpenCV's RQ leaves the signs of the focal lengths free: normalised here)."""
    rng = np.random.default_rng(4)
    io = pg.InteriorOrientation(100.0, -0.05, 0.03)
    eo = pg.ExteriorOrientation(100.0, 200.0, 900.0, *np.radians(angles))
    n = 20
    xn = rng.uniform(-0.45, 0.45, (n, 2))
    rays = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(n)]) * rng.uniform(300, 1500, (n, 1))
    g = eo.position + rays @ eo.matrix
    fit = pg.estimate_dlt(g, pg.project(g, io, eo) + rng.normal(0.0, 0.005, (n, 2)), sigma=0.005)
    K, R, C = cv2.decomposeProjectionMatrix(np.diag([1.0, -1.0, 1.0]) @ fit.camera_matrix)[:3]
    K = K / K[2, 2]
    S = np.diag([np.sign(K[0, 0]), np.sign(K[1, 1]), 1.0])
    K, R = K @ S, S @ R
    i, e = fit.interior, fit.exterior
    np.testing.assert_allclose(e.position, C[:3, 0] / C[3, 0], atol=1e-9)
    np.testing.assert_allclose(e.matrix, FLIP @ R, atol=1e-12)
    np.testing.assert_allclose([i.fx, i.fy, i.x0, -i.y0, i.b2],
                               [K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1]], atol=1e-9)
    assert i.fx == pytest.approx(100.0, rel=1e-3) and i.x0 == pytest.approx(-0.05, abs=0.1)
