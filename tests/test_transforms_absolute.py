"""3D similarity and rigid estimation through the absolute orientation (SVD)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg

pytest.importorskip(
    "photogeom.orientation.absolute",
    reason="photogeom.orientation.absolute (absolute_orientation) is not available yet",
)


def test_example_8_recovered():
    true = pg.Similarity3D.from_angles(1.0, 10.0, 15.0, 50.0, [-200, 136, 189], unit="deg")
    src = np.array([[1354, 547, 135], [100, -20, 30], [-500, 800, 10], [20, 30, -400.0]])
    fit = pg.estimate_transform("similarity3d", src, true.apply(src), unit="m")
    assert isinstance(fit.model, pg.Similarity3D)
    np.testing.assert_allclose(fit.model.rotation, true.rotation, atol=1e-12)
    np.testing.assert_allclose(fit.model.translation, true.translation, atol=1e-9)
    assert fit.model.scale == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(fit.model.apply([1354, 547, 135]), (270.8707, 1501.3692, 443.5540),
                               atol=5e-5)
    assert fit.residual_unit == "m"


def test_rigid3d_has_no_scale():
    true = pg.Rigid3D.from_angles(0.3, -1.2, 2.8, [10.0, -20.0, 5.0])
    rng = np.random.default_rng(4)
    src = rng.uniform(-50, 50, (8, 3))
    dst = true.apply(src) + rng.normal(0, 1e-3, (8, 3))
    fit = pg.estimate_transform("rigid3d", src, dst)
    assert isinstance(fit.model, pg.Rigid3D) and fit.scale == 1.0
    assert "scale" not in fit.parameter_names
    np.testing.assert_allclose(fit.model.rotation, true.rotation, atol=1e-4)
    np.testing.assert_allclose(fit.residuals, fit.model.apply(src) - dst, atol=1e-12)


def test_utm_sized_target_recovered_to_1e9():
    rng = np.random.default_rng(7)
    model_pts = rng.uniform(-1, 1, (20, 3))
    true = pg.Similarity3D.from_angles(812.5, 0.02, -0.03, 2.1, [512_345.678, 4_012_345.678, 310.2])
    fit = pg.estimate_transform("similarity3d", model_pts, true.apply(model_pts))
    assert fit.model.scale == pytest.approx(true.scale, rel=1e-9)
    np.testing.assert_allclose(fit.model.translation, true.translation, rtol=1e-9)
    np.testing.assert_allclose(fit.model.rotation, true.rotation, atol=1e-9)


def test_check_points_and_ids():
    true = pg.Similarity3D.from_angles(2.0, 0.1, 0.2, 0.3, [1.0, 2.0, 3.0])
    rng = np.random.default_rng(9)
    src = rng.uniform(-10, 10, (9, 3))
    dst = true.apply(src) + rng.normal(0, 0.01, (9, 3))
    chk = np.zeros(9, bool)
    chk[[2, 6]] = True
    ids = [f"P{i}" for i in range(9)]
    fit = pg.estimate_transform("similarity3d", src, dst, check=chk, ids=ids)
    assert fit.check_ids == ("P2", "P6") and len(fit.ids) == 7
    np.testing.assert_allclose(fit.check_residuals, fit.model.apply(src[chk]) - dst[chk])
    alone = pg.estimate_transform("similarity3d", src[~chk], dst[~chk])
    np.testing.assert_allclose(alone.model.rotation, fit.model.rotation, atol=1e-14)


def test_helmert_parameters_of_an_estimate():
    # pairs generated with published position-vector parameters are estimated back
    published = (-446.448, 125.157, -542.060, -0.1502, -0.2470, -0.8421, 20.4894)
    true = pg.Similarity3D.from_helmert(*published, convention="position_vector")
    rng = np.random.default_rng(2)
    ecef = np.array([4_027_894.0, 307_045.0, 4_919_474.0]) + rng.uniform(-5e4, 5e4, (10, 3))
    fit = pg.estimate_transform("similarity3d", ecef, true.apply(ecef))
    hp = fit.extras["helmert"]["position_vector"]
    got = [hp[k][0] for k in ("tx", "ty", "tz", "rx", "ry", "rz", "ds")]
    np.testing.assert_allclose(got, published, rtol=1e-6, atol=1e-6)
    cf = fit.extras["helmert"]["coordinate_frame"]
    assert cf["rx"][0] == pytest.approx(-published[3], abs=1e-5)  # equal to first order


@settings(max_examples=20, deadline=None)
@given(w=st.floats(-np.pi, np.pi), p=st.floats(-1.55, 1.55), k=st.floats(-np.pi, np.pi),
       s=st.floats(0.01, 100), seed=st.integers(0, 2**31))
def test_noise_free_recovery(w, p, k, s, seed):
    rng = np.random.default_rng(seed)
    true = pg.Similarity3D.from_angles(s, w, p, k, rng.uniform(-1e4, 1e4, 3))
    src = rng.uniform(-100, 100, (10, 3))
    fit = pg.estimate_transform("similarity3d", src, true.apply(src))
    np.testing.assert_allclose(fit.model.rotation, true.rotation, atol=1e-9)
    assert fit.model.scale == pytest.approx(s, rel=1e-9)
    rig = pg.Rigid3D(true.rotation, true.translation)
    rfit = pg.estimate_transform("rigid3d", src, rig.apply(src))
    np.testing.assert_allclose(rfit.model.rotation, true.rotation, atol=1e-9)
