"""Absolute orientation against published numbers and across methods on the bundled data."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom import datasets
from photogeom.orientation import METHODS
from photogeom.rotation import opk_matrix

LSQ = ("svd", "quaternion", "dual-quaternion", "gauss-markov")


def _pairs(name, kind=None):
    _, x, X = datasets.point_pairs(name, kind)
    return x, X


@pytest.mark.parametrize("method", [*LSQ, "gauss-helmert"])
def test_kraus_gon_angles_transposed(method):
    # Kraus (2007) via the Gauss-Helmert paper: -0.1854, -1.0920, 298.6799 gon (transposed)
    fit = pg.absolute_orientation(*_pairs("kraus_absolute_orientation"), method)
    w, p, k = fit.angles("transposed", "gon")
    assert round(w, 4) == -0.1854
    assert round(p, 4) == -1.0920
    assert round(k % 400.0, 4) == 298.6799
    # the transposed convention: R = M(omega, phi, kappa).T, the parameters are those angles
    ang = [fit.params[a] for a in ("omega", "phi", "kappa")]
    np.testing.assert_allclose(fit.rotation, opk_matrix(*ang).T, atol=1e-15)


def test_kraus_closed_form_close_to_least_squares():
    x, X = _pairs("kraus_absolute_orientation")
    cf = pg.absolute_orientation(x, X, "closed-form")
    w, p, k = cf.angles("transposed", "gon")
    np.testing.assert_allclose([w, p, k % 400], [-0.1854, -1.0920, 298.6799], atol=2e-3)
    assert 1e-5 < cf.orthogonality_defect < 1e-2  # raw R, kept as published
    assert any("augmentation" in n for n in cf.notes)  # n = 3


@pytest.mark.parametrize("method", METHODS)
def test_afary_true_parameters_recovered_by_every_method(method):
    # s = 4, t = (250, 250, 250) m, (Omega, Phi, K) = (50, 60, 130) deg, direct convention;
    # the "error-free" coordinates are printed to 4 decimals
    fit = pg.absolute_orientation(*_pairs("afary2024_simulated", "true"), method)
    np.testing.assert_allclose(fit.angles("direct", "deg"), [50, 60, 130], atol=1e-3)
    assert fit.scale == pytest.approx(4.0, rel=2e-6)
    np.testing.assert_allclose(fit.translation, [250, 250, 250], atol=2e-3)


def test_afary_closed_form_nearest_rotation_option():
    fit = pg.absolute_orientation(
        *_pairs("afary2024_simulated", "true"), "closed-form", nearest_rotation=True
    )
    assert fit.orthogonality_defect < 1e-14
    np.testing.assert_allclose(fit.angles("direct", "deg"), [50, 60, 130], atol=1e-3)


def test_afary_noisy_closed_form_near_least_squares():
    x, X = _pairs("afary2024_simulated", "noisy")
    cf = pg.absolute_orientation(x, X, "closed-form")
    ls = pg.absolute_orientation(x, X, "gauss-markov")
    d = np.array(cf.angles("direct", "deg")) - np.array(ls.angles("direct", "deg"))
    assert np.max(np.abs(d)) < 0.1
    assert np.max(np.abs(cf.translation - ls.translation)) < 0.5


@pytest.mark.parametrize(
    "name,kind",
    [("lidar_wang2014", None), ("kraus_absolute_orientation", None),
     ("afary2024_simulated", "true"), ("afary2024_simulated", "noisy")],
)
def test_least_squares_methods_agree(name, kind):
    x, X = _pairs(name, kind)
    ref = pg.absolute_orientation(x, X, "gauss-markov")
    assert ref.converged
    # the converged shift is exactly Xg - s R xg
    np.testing.assert_allclose(
        ref.translation, X.mean(0) - ref.scale * ref.rotation @ x.mean(0), rtol=1e-12, atol=1e-9
    )
    for m in ("svd", "quaternion", "dual-quaternion"):
        fit = pg.absolute_orientation(x, X, m)
        assert fit.scale == pytest.approx(ref.scale, rel=1e-9)
        np.testing.assert_allclose(fit.rotation, ref.rotation, atol=1e-9)
        np.testing.assert_allclose(
            fit.translation, ref.translation, atol=1e-9 * np.abs(ref.translation).max()
        )


def test_lidar_closed_form_accuracy_and_gauss_helmert_rotation():
    x, X = _pairs("lidar_wang2014")
    ls = pg.absolute_orientation(x, X, "gauss-markov")
    cf = pg.absolute_orientation(x, X, "closed-form")
    d = np.array(cf.angles("transposed", "deg")) - np.array(ls.angles("transposed", "deg"))
    assert np.max(np.abs(d)) < 0.2  # the paper: ~0.02 deg for its data
    assert np.max(np.abs(cf.translation - ls.translation)) < 0.2
    gh = pg.absolute_orientation(x, X, "gauss-helmert")
    np.testing.assert_allclose(gh.rotation, ls.rotation, atol=1e-12)  # same rotation
    assert gh.scale != pytest.approx(ls.scale, rel=1e-9)  # scale (and shift) differ


def test_residuals_computed_minus_observed_and_statistics():
    x, X = _pairs("lidar_wang2014")
    fit = pg.absolute_orientation(x, X)
    np.testing.assert_allclose(fit.residuals, fit.transform.apply(x) - X, atol=1e-12)
    assert fit.redundancy == 3 * 18 - 7
    assert fit.sigma0 == pytest.approx(
        np.sqrt(np.sum(fit.residuals**2) / fit.redundancy), rel=1e-12
    )
    assert set(fit.std_errors) == {"tx", "ty", "tz", "scale", "omega", "phi", "kappa"}
    assert fit.parameter_units["kappa"] == "rad"
    # the redundancy numbers add up to the redundancy
    assert np.sum(fit.redundancy_numbers) == pytest.approx(fit.redundancy, rel=1e-10)
    d = fit.to_dict()
    assert d["parameters"]["scale"]["value"] == pytest.approx(fit.scale)


def test_utm_sized_target_recovers_parameters_to_1e9():
    # model coordinates of order 1, target UTM-sized (northing ~ 4e6 m)
    rng = np.random.default_rng(11)
    x = rng.uniform(-1, 1, (12, 3))
    R = opk_matrix(0.3, -1.1, 2.7).T
    s, t = 2345.678, np.array([512345.678, 4123456.789, 312.5])
    X = s * x @ R.T + t
    for m in ("svd", "quaternion", "dual-quaternion", "gauss-markov", "gauss-helmert"):
        fit = pg.absolute_orientation(x, X, m)
        assert fit.scale == pytest.approx(s, rel=1e-9), m
        np.testing.assert_allclose(fit.rotation, R, atol=1e-9, err_msg=m)
        np.testing.assert_allclose(fit.translation, t, rtol=1e-9, err_msg=m)
    fit = pg.absolute_orientation(x, X, "closed-form")
    assert fit.scale == pytest.approx(s, rel=1e-9)
    np.testing.assert_allclose(fit.rotation, R, atol=1e-9)
    np.testing.assert_allclose(fit.translation, t, rtol=1e-9)
    # the large-n one-pass path detects the cancellation and centres first
    xs = np.repeat(x, 6000, axis=0) + rng.normal(scale=1e-3, size=(72000, 3))
    Xs = s * xs @ R.T + t
    fast = pg.absolute_orientation(xs, Xs, statistics=False)
    assert fast.scale == pytest.approx(s, rel=1e-9)
    np.testing.assert_allclose(fast.translation, t, rtol=1e-9)


def test_estimate_transform_similarity3d_is_the_svd_solution():
    est = pytest.importorskip("photogeom.estimation.transforms")
    if not hasattr(est, "estimate_transform"):
        pytest.skip("estimate_transform is not available")
    x, X = _pairs("lidar_wang2014")
    ref = pg.absolute_orientation(x, X, "svd")
    fit = est.estimate_transform("similarity3d", x, X)
    assert fit.model.scale == pytest.approx(ref.scale, rel=1e-12)
    np.testing.assert_allclose(fit.model.rotation, ref.rotation, atol=1e-12)
    np.testing.assert_allclose(fit.model.translation, ref.translation, atol=1e-9)
    rig = est.estimate_transform("rigid3d", x, X)
    ref_r = pg.absolute_orientation(x, X, "svd", with_scale=False)
    np.testing.assert_allclose(rig.model.rotation, ref_r.rotation, atol=1e-12)
