"""Brown distortion as Metashape defines it: formulas, inverse, conventions, XML, OpenCV."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.camera.metashape import MetashapeXMLWarning
from photogeom.errors import ConvergenceError, FileFormatError, InputError

#: Realistic coefficients of a 48 MP UAV camera (8000 x 6000 px, 24 mm lens, 4.3 um pixels).
UAV = dict(
    width=8000,
    height=6000,
    f=5600.0,
    cx=12.3,
    cy=-8.7,
    k1=-0.11,
    k2=0.12,
    k3=-0.04,
    k4=0.005,
    p1=3e-4,
    p2=-2e-4,
    b1=0.6,
    b2=-0.3,
)


def uav(**kw):
    return pg.MetashapeCalibration(**{**UAV, **kw})


def literal_metashape(c, x, y):
    """Metashape's frame-camera equations written out literally (pixel origin: corner)."""
    r2 = x * x + y * y
    rad = 1 + c.k1 * r2 + c.k2 * r2**2 + c.k3 * r2**3 + c.k4 * r2**4
    xp = x * rad + (c.p1 * (r2 + 2 * x * x) + 2 * c.p2 * x * y)
    yp = y * rad + (c.p2 * (r2 + 2 * y * y) + 2 * c.p1 * x * y)
    u = c.width * 0.5 + c.cx + xp * c.f + xp * c.b1 + yp * c.b2
    v = c.height * 0.5 + c.cy + yp * c.f
    return np.column_stack([u, v])


def test_forward_equals_the_manufacturers_formula():
    c = uav()
    xy = np.random.default_rng(0).uniform(-0.8, 0.8, (1000, 2))
    np.testing.assert_allclose(
        c.project_normalized(xy, pixel_origin="corner"),
        literal_metashape(c, xy[:, 0], xy[:, 1]),
        rtol=0,
        atol=1e-9,
    )


def test_pixel_origin_pinned():
    c = uav()
    # The principal point is (w/2 + cx, h/2 + cy) from the top-left corner (Metashape) and
    # half a pixel less with the top-left pixel's centre at (0, 0) (photogeom, OpenCV).
    np.testing.assert_allclose(
        c.project_normalized([[0.0, 0.0]], pixel_origin="corner"), [[4012.3, 2991.3]], atol=1e-12
    )
    np.testing.assert_allclose(c.project_normalized([[0.0, 0.0]]), [[4011.8, 2990.8]], atol=1e-12)
    assert c.principal_point("center") == pytest.approx((4011.8, 2990.8))
    io = c.interior_orientation()
    assert io.principal_point_px("center") == pytest.approx((4011.8, 2990.8))
    assert io.principal_point_px("corner") == pytest.approx((4012.3, 2991.3))


def test_camera_axes_metashape_vs_photogrammetric():
    # Metashape: x right, y down, z forward. Photogrammetric: x right, y up, camera looking
    # along -z. The same physical point (X, Y, Z)_metashape is (X, -Y, -Z) photogrammetric.
    c = uav()
    rng = np.random.default_rng(1)
    P = np.column_stack([rng.uniform(-4, 4, 200), rng.uniform(-3, 3, 200), rng.uniform(5, 50, 200)])
    uv = c.project_camera(P)
    io = c.interior_orientation()
    eo = pg.ExteriorOrientation(0, 0, 0)  # camera frame = object frame
    pgxy = pg.project(P * [1.0, -1.0, -1.0], io, eo, system="pixel")
    np.testing.assert_allclose(pgxy, uv, rtol=0, atol=1e-8)
    # a point right of and below the optical axis lands right of and below the principal point
    u, v = c.project_camera([[1.0, 1.0, 10.0]])[0]
    u0, v0 = c.principal_point()
    assert u > u0 and v > v0
    with pytest.raises(pg.DegenerateGeometryError, match="Z <= 0"):
        c.project_camera([[0.0, 0.0, -1.0]])


def test_projection_equals_opencv_projectpoints():
    c = uav(k4=0.0, b2=0.0)  # the terms OpenCV shares
    K, dist = c.to_opencv()
    rng = np.random.default_rng(2)
    # a ground scene and an oblique camera; OpenCV's camera frame = diag(1, -1, -1) M (X - X0)
    eo = pg.ExteriorOrientation.from_degrees(500.0, 300.0, 120.0, 25.0, -10.0, 70.0)
    xn = rng.uniform(-0.6, 0.6, (5000, 2))
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(5000)]) * rng.uniform(20, 300, (5000, 1))
    ground = eo.position + pc @ eo.matrix
    D = np.diag([1.0, -1.0, -1.0])
    R = D @ eo.matrix
    rvec, _ = cv2.Rodrigues(R)
    tvec = -R @ eo.position
    uv_cv, _ = cv2.projectPoints(ground, rvec, tvec, K, dist)
    ours = pg.project(ground, c.interior_orientation(), eo, system="pixel")
    np.testing.assert_allclose(ours, uv_cv[:, 0], rtol=0, atol=1e-7)
    # and Metashape-frame camera coordinates straight into both
    P = ground @ R.T + tvec
    np.testing.assert_allclose(c.project_camera(P), uv_cv[:, 0], rtol=0, atol=1e-7)


def test_opencv_conversion_exact_and_refusals():
    c = uav(k4=0.0, b2=0.0)
    K, dist = c.to_opencv()
    assert K[0, 0] == pytest.approx(c.f + c.b1) and K[1, 1] == c.f
    assert dist[2] == c.p2 and dist[3] == c.p1  # OpenCV's p1, p2 are Metashape's P2, P1
    assert K[0, 2] == pytest.approx(8000 / 2 + c.cx - 0.5)
    back = pg.MetashapeCalibration.from_opencv(K, dist, 8000, 6000)
    for name in ("f", "cx", "cy", "k1", "k2", "k3", "p1", "p2", "b1"):
        assert getattr(back, name) == pytest.approx(getattr(c, name), rel=1e-12, abs=1e-12)
    with pytest.raises(InputError, match="K4, B2 have no OpenCV equivalent"):
        uav().to_opencv()
    with pytest.raises(InputError, match="no Metashape equivalent"):
        pg.MetashapeCalibration.from_opencv(K, [0.1, 0, 0, 0, 0, 0.2, 0, 0], 8000, 6000)
    K2 = K.copy()
    K2[0, 1] = 1.0
    with pytest.raises(InputError, match="skew"):
        pg.MetashapeCalibration.from_opencv(K2, dist, 8000, 6000)


def test_interior_orientation_round_trip():
    c = uav()
    io = c.interior_orientation()
    assert io.unit == "px" and io.fx == c.f + c.b1 and io.b2 == c.b2
    back = pg.MetashapeCalibration.from_interior_orientation(io)
    for name, value in UAV.items():
        assert getattr(back, name) == pytest.approx(value, rel=1e-13, abs=1e-12), name


def _grid(step):
    cols = np.unique(np.concatenate([np.arange(0, 8000, step), [0, 1, 7998, 7999]]))
    rows = np.unique(np.concatenate([np.arange(0, 6000, step), [0, 1, 5998, 5999]]))
    u, v = np.meshgrid(cols.astype(float), rows.astype(float))
    border = np.concatenate(
        [
            np.column_stack([np.arange(8000.0), np.zeros(8000)]),
            np.column_stack([np.arange(8000.0), np.full(8000, 5999.0)]),
            np.column_stack([np.zeros(6000), np.arange(6000.0)]),
            np.column_stack([np.full(6000, 7999.0), np.arange(6000.0)]),
        ]
    )
    return np.vstack([np.column_stack([u.ravel(), v.ravel()]), border])


def test_forward_then_inverse_returns_every_pixel():
    # Dense grid over the whole 8000 x 6000 image (every 4th pixel plus every border pixel,
    # where distortion is largest), vectorised.
    c = uav()
    uv = _grid(4)
    assert uv.shape[0] > 3_000_000
    # ideal pixel -> distorted pixel -> back
    distorted = c.distort_pixels(uv)
    res = c.undistort_pixels(distorted, tol=1e-9)
    assert res.all_converged
    assert np.max(np.abs(res.points - uv)) < 1e-6
    # observed pixel -> normalised ray -> re-projected pixel
    res2 = c.unproject(uv, tol=1e-9)
    assert res2.all_converged and res2.iterations < 10
    assert np.max(np.abs(c.project_normalized(res2.points) - uv)) < 1e-6
    assert np.max(res2.residual) < 1e-6


def test_undistortion_reports_non_convergence():
    # strong barrel distortion folds over beyond r = 1/sqrt(3 * 0.5): no inverse out there
    d = pg.BrownDistortion(k1=-0.5)
    pts = np.array([[0.2, 0.1], [0.7, 0.0], [0.0, 0.9]])
    res = d.undistort(pts, max_iter=20)
    assert res.status[0] == 0
    assert np.all(res.status[1:] != 0)
    assert "not undistorted" in res.describe_failures()
    io = pg.InteriorOrientation(1000.0, unit="px", distortion=d)
    with pytest.raises(ConvergenceError, match="not undistorted"):
        io.normalized_from_image(pts * [1000, -1000])
    out = io.normalized_from_image(pts * [1000, -1000], on_failure="nan")
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1:]))


def test_distortion_jacobian_and_zero_model():
    d = pg.BrownDistortion(-0.1, 0.05, -0.01, 0.002, 3e-4, -2e-4)
    xy = np.random.default_rng(4).uniform(-0.6, 0.6, (50, 2))
    J = d.jacobian(xy)
    h = 1e-7
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        num = (d.distort(xy + e) - d.distort(xy - e)) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], num, atol=1e-7)
    z = pg.BrownDistortion()
    assert z.is_zero and np.all(z.undistort(xy).points == xy)
    with pytest.raises(InputError, match="unknown distortion"):
        pg.BrownDistortion.from_dict({"k5": 1.0})


def test_xml_round_trip_and_atomic_write(tmp_path):
    c = uav()
    path = tmp_path / "calib.xml"
    pg.write_metashape_xml(c, path)
    text = path.read_text()
    assert text.startswith('<?xml version="1.0" encoding="UTF-8"?>')
    for tag in (
        "projection",
        "width",
        "height",
        "f",
        "cx",
        "cy",
        "k1",
        "k2",
        "k3",
        "k4",
        "p1",
        "p2",
        "b1",
        "b2",
    ):
        assert f"<{tag}>" in text
    assert pg.read_metashape_xml(path) == c
    # rewriting replaces the file completely; no temporary files are left behind
    pg.write_metashape_xml(uav(f=4000.0), path)
    assert pg.read_metashape_xml(path).f == 4000.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calib.xml"]
    with pytest.raises(pg.PhotogeomError, match="does not exist"):
        pg.write_metashape_xml(c, tmp_path / "missing" / "c.xml")


METASHAPE_EXPORT = """<?xml version="1.0" encoding="UTF-8"?>
<calibration>
  <projection>frame</projection>
  <width>5472</width>
  <height>3648</height>
  <f>3648.5</f>
  <cx>-10.25</cx>
  <cy>14.5</cy>
  <k1>-0.0123</k1>
  <k2>0.0091</k2>
  <p1>-0.0002</p1>
  <p2>0.0001</p2>
  <date>2024-03-01T10:00:00Z</date>
</calibration>
"""


def test_xml_reads_metashape_export_and_project_form():
    c = pg.MetashapeCalibration.from_xml_string(METASHAPE_EXPORT)
    assert (c.width, c.height, c.f, c.cx, c.cy) == (5472, 3648, 3648.5, -10.25, 14.5)
    assert c.k3 == 0.0 and c.b1 == 0.0 and c.p1 == -0.0002
    project_form = (
        '<calibration type="frame" class="adjusted"><resolution width="4096" height="3072"/>'
        "<f>3219.66</f><cx>15.06</cx><cy>18.67</cy><k1>0.0208</k1></calibration>"
    )
    c2 = pg.MetashapeCalibration.from_xml_string(project_form)
    assert (c2.width, c2.height, c2.f, c2.k1) == (4096, 3072, 3219.66, 0.0208)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (METASHAPE_EXPORT.replace("<f>3648.5</f>", ""), "missing required tag"),
        (METASHAPE_EXPORT.replace("frame", "fisheye"), "not supported"),
        (METASHAPE_EXPORT.replace("<projection>frame</projection>", ""), "missing <projection>"),
        (METASHAPE_EXPORT.replace("3648.5", "abc"), "not a number"),
        (METASHAPE_EXPORT.replace("<width>5472</width>", "<width>54.5</width>"), "whole number"),
        (METASHAPE_EXPORT.replace("<k1>", "<p3>0.1</p3><k1>"), "P1, P2 only"),
        ("<calibration><f>1</f>", "not well-formed"),
        ("<camera/>", "expected <calibration>"),
    ],
)
def test_xml_errors(text, message):
    with pytest.raises(FileFormatError, match=message):
        pg.MetashapeCalibration.from_xml_string(text)


def test_xml_unknown_tags_warn_or_fail(tmp_path):
    text = METASHAPE_EXPORT.replace("<k1>", "<k7>0.5</k7><k1>")
    with pytest.warns(MetashapeXMLWarning, match="<k7>"):
        c = pg.MetashapeCalibration.from_xml_string(text)
    assert c.k1 == -0.0123
    path = tmp_path / "x.xml"
    path.write_text(text)
    with pytest.raises(FileFormatError, match="unknown tag"):
        pg.read_metashape_xml(path, strict=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pg.MetashapeCalibration.from_xml_string(METASHAPE_EXPORT)  # known tags: no warning
    with pytest.raises(FileFormatError, match="cannot read"):
        pg.read_metashape_xml(tmp_path / "nope.xml")


@settings(max_examples=60, deadline=None)
@given(
    k=st.tuples(
        st.floats(-0.3, 0.3), st.floats(-0.2, 0.2), st.floats(-0.1, 0.1), st.floats(-0.05, 0.05)
    ),
    p=st.tuples(st.floats(-1e-3, 1e-3), st.floats(-1e-3, 1e-3)),
    seed=st.integers(0, 2**31 - 1),
)
def test_undistort_inverts_distort_for_random_models(k, p, seed):
    d = pg.BrownDistortion(*k, *p)
    xy = np.random.default_rng(seed).uniform(-0.42, 0.42, (500, 2))  # r <= 0.6
    res = d.undistort(d.distort(xy), tol=1e-13)
    assert res.all_converged, res.describe_failures()
    np.testing.assert_allclose(res.points, xy, rtol=0, atol=1e-12)
