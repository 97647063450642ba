"""Reported statistics of the rigid (6-parameter) 3D transformation and of the fiducial
(interior orientation) fit against the spread of redrawn noise.

300 redraws on a fixed geometry: a standard deviation has a sampling error of about 4 %
(each ratio allowed 0.8-1.2, their median 0.9-1.1), the mean sigma0^2 about 2 % (0.08
allowed), the 5 % rejection rate of Baarda's w-test about 0.4 % (1.5 % allowed). Angles are
compared on the circle: the rotation has omega and kappa within 0.1 degree of +-180 degrees.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg

TRIALS = 300
SIGMA = 0.01
ANGLES = np.radians([179.9, 5.0, -179.9])  # transposed convention, omega/kappa at the wrap


def _unwrap(P: np.ndarray, angle_columns: slice) -> np.ndarray:
    P = P.copy()
    ref = P[0, angle_columns]
    P[:, angle_columns] = ref + (P[:, angle_columns] - ref + np.pi) % (2 * np.pi) - np.pi
    return P


def _check(fits, angle_columns: slice | None):
    s02 = np.mean([(f.sigma0 / f.sigma0_prior) ** 2 for f in fits])
    assert s02 == pytest.approx(1.0, abs=0.08)
    P = np.array([f.parameters for f in fits])
    if angle_columns is not None:
        P = _unwrap(P, angle_columns)
    std = np.sqrt(np.mean([np.diag(f.covariance_prior) for f in fits], axis=0))
    ratio = P.std(axis=0, ddof=1) / std
    names = fits[0].parameter_names
    assert np.all((ratio > 0.8) & (ratio < 1.2)), dict(zip(names, ratio.round(3)))
    assert np.median(ratio) == pytest.approx(1.0, abs=0.1)
    w = np.abs(np.array([f.normalized_residuals for f in fits]))
    assert np.mean(w > 1.959964) == pytest.approx(0.05, abs=0.015)
    return ratio


def _rigid_scene(seed=3, n=10):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-50.0, 50.0, (n, 3))
    R = pg.rotation_from_angles(*ANGLES, convention="transposed")
    X = x @ R.T + np.array([4.2e5, 5.1e6, 310.0])
    return rng, x, X


@pytest.mark.parametrize("method", ["svd", "quaternion", "dual-quaternion", "gauss-markov"])
def test_rigid_absolute_orientation(method):
    rng, x, X = _rigid_scene()
    fits = [
        pg.absolute_orientation(x, X + rng.normal(0.0, SIGMA, X.shape), method,
                                with_scale=False, sigma_target=SIGMA)
        for _ in range(TRIALS)
    ]  # fmt: skip
    assert fits[0].parameter_names == ("tx", "ty", "tz", "omega", "phi", "kappa")
    np.testing.assert_allclose(fits[0].angles(), ANGLES, atol=1e-3)
    _check(fits, slice(3, 6))


def test_rigid_gauss_helmert_with_errors_in_both_systems():
    rng, x, X = _rigid_scene(seed=4)
    sx, sX = 0.004, SIGMA
    fits = [
        pg.absolute_orientation(x + rng.normal(0.0, sx, x.shape),
                                X + rng.normal(0.0, sX, X.shape), "gauss-helmert",
                                with_scale=False, sigma_source=sx, sigma_target=sX)
        for _ in range(TRIALS)
    ]  # fmt: skip
    _check(fits, slice(3, 6))


def test_rigid3d_transformation():
    rng, x, X = _rigid_scene(seed=5)
    fits = [
        pg.estimate_transform("rigid3d", x, X + rng.normal(0.0, SIGMA, X.shape),
                              sigma0_prior=SIGMA)
        for _ in range(TRIALS)
    ]  # fmt: skip
    assert len(fits[0].parameters) == 6
    _check(fits, None)  # rigid3d parameters: shift and rotation vector, no wrap


# --- interior orientation: fiducial marks measured in pixels (left-handed) -------------------

CALIBRATED = np.array(
    [[-106.0, -106.0], [106.0, 106.0], [-106.0, 106.0], [106.0, -106.0],
     [0.0, 110.0], [0.0, -110.0], [110.0, 0.0], [-110.0, 0.0]]
)  # fmt: skip


@pytest.mark.parametrize("model", ["similarity", "affine", "projective"])
def test_fiducials_measured_in_pixels(model):
    """Scanned photograph at 12 um, turned by 179.5 degrees in the scanner: the pixel rows
    are negated before the fit (a right-handed system); the parameters, their textbook
    form and the tests follow the redraws of the calibrated-mark noise (0.003 mm)."""
    rng = np.random.default_rng(9)
    sigma = 0.003
    # fiducial -> pixel: 1 / 0.012 pixels per mm, turned by 179.5 degrees; rows grow downwards
    mm_to_pix = pg.Similarity2D.from_textbook(1.0 / 0.012, np.radians(179.5), 5100.0, -4900.0)
    measured = mm_to_pix.apply(CALIBRATED) * [1.0, -1.0]
    fits = [
        pg.fit_fiducials(measured, CALIBRATED + rng.normal(0.0, sigma, CALIBRATED.shape),
                         model=model, measured_system="pixel", sigma0_prior=sigma)
        for _ in range(TRIALS)
    ]  # fmt: skip
    assert fits[0].extras["handedness"]["source_flip_y"]
    np.testing.assert_allclose(
        pg.camera.measured_to_fiducial(fits[0], measured), CALIBRATED, atol=0.02
    )
    _check(fits, None)
    textbook = fits[0].extras.get("textbook")
    if textbook:
        names = list(textbook)
        T = np.array([[f.extras["textbook"][k][0] for k in names] for f in fits])
        if "theta" in names:
            T = _unwrap(T, slice(names.index("theta"), names.index("theta") + 1))
        ts = np.sqrt(np.mean([[f.extras["textbook"][k][1] ** 2 for k in names] for f in fits],
                             axis=0))  # fmt: skip
        s0 = np.sqrt(np.mean([(f.sigma0 / f.sigma0_prior) ** 2 for f in fits]))
        ratio = T.std(axis=0, ddof=1) / (ts / s0)  # textbook std are a posteriori
        ok = np.isfinite(ratio)
        assert np.all((ratio[ok] > 0.8) & (ratio[ok] < 1.2)), dict(zip(names, ratio.round(3)))
