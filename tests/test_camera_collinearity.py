"""Collinearity equations, interior/exterior orientation and pixel conventions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.camera.collinearity import projection_derivatives
from photogeom.errors import DegenerateGeometryError, InputError

GROUND = np.array([1300.0, 650.0, 169.0])


def aerial():
    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    eo = pg.ExteriorOrientation.from_degrees(1114, 862, 1600, 2, 3, 10)
    return io, eo


def test_spec_collinearity_example():
    io, eo = aerial()
    x, y = pg.project(GROUND, io, eo)
    assert round(x, 4) == 22.7354
    assert round(y, 4) == -32.7917


def test_spec_example_against_written_out_formula():
    # Independent of the library's rotation code: the matrix of 01-conventions.md typed out.
    w, p, k = np.radians([2.0, 3.0, 10.0])
    sw, cw, sp, cp, sk, ck = np.sin(w), np.cos(w), np.sin(p), np.cos(p), np.sin(k), np.cos(k)
    M = np.array(
        [
            [ck * cp, ck * sp * sw + sk * cw, -ck * sp * cw + sk * sw],
            [-sk * cp, -sk * sp * sw + ck * cw, sk * sp * cw + ck * sw],
            [sp, -cp * sw, cp * cw],
        ]
    )
    d = GROUND - np.array([1114.0, 862.0, 1600.0])
    x = 0.008 - 152.14 * (M[0] @ d) / (M[2] @ d)
    y = -0.12 - 152.14 * (M[1] @ d) / (M[2] @ d)
    io, eo = aerial()
    np.testing.assert_allclose(pg.project(GROUND, io, eo), [x, y], rtol=0, atol=1e-12)


def test_spec_digital_camera_example():
    io = pg.InteriorOrientation.digital(10000, 3840, 6912, pixel_size=0.012)
    eo = pg.ExteriorOrientation.from_degrees(1160, 792, 1500, 1.5, 2, 4)
    col, row = pg.project(GROUND, io, eo, system="pixel")
    assert round(col, 1) == 5152.8
    assert round(row, 1) == 8345.3
    # The same camera in millimetres (f = 10000 px * 0.012 mm = 120 mm) gives the same pixel.
    io_mm = pg.InteriorOrientation.digital(120.0, 3840, 6912, pixel_size=0.012, unit="mm")
    np.testing.assert_allclose(
        pg.project(GROUND, io_mm, eo, system="pixel"), [col, row], rtol=0, atol=1e-9
    )
    xy_mm = pg.project(GROUND, io_mm, eo)
    np.testing.assert_allclose(xy_mm, [(col - 3840) * 0.012, -(row - 6912) * 0.012], atol=1e-12)


def test_pixel_conventions_pinned():
    io = pg.InteriorOrientation.digital(1000, 100.0, 50.0)
    # principal point maps to the image origin; rows grow downwards, y upwards
    np.testing.assert_allclose(io.pixel_to_image([100.0, 50.0]), [0.0, 0.0])
    np.testing.assert_allclose(io.pixel_to_image([101.0, 49.0]), [1.0, 1.0])
    # corner convention: the top-left pixel's centre is (0.5, 0.5)
    np.testing.assert_allclose(io.pixel_to_image([100.5, 50.5], "corner"), [0.0, 0.0])
    np.testing.assert_allclose(io.image_to_pixel([0.0, 0.0], "corner"), [100.5, 50.5])
    # principal point given in the corner convention
    io_c = pg.InteriorOrientation.digital(1000, 100.5, 50.5, pixel_origin="corner")
    assert io_c.origin_px == (100.0, 50.0)
    with pytest.raises(InputError, match="pixel_origin"):
        io.image_to_pixel([0, 0], "middle")


def test_fx_differs_from_fy():
    io = pg.InteriorOrientation.digital(1000.0, 0.0, 0.0, fy=900.0)
    assert io.fx == 1000.0 and io.fy == 900.0
    eo = pg.ExteriorOrientation(0, 0, 10)
    # a point 1 m right and 1 m up (camera looking straight down): x = fx * 0.1, y = fy * 0.1
    np.testing.assert_allclose(pg.project([1.0, 1.0, 0.0], io, eo), [100.0, 90.0], atol=1e-12)
    io2 = pg.InteriorOrientation.from_focal_lengths(1000.0, 900.0, unit="px")
    assert io2.b1 == 100.0


def test_nadir_geometry_signs():
    # camera 1000 m above the origin looking down; a point east of nadir images at +x
    io = pg.InteriorOrientation(100.0)
    eo = pg.ExteriorOrientation(0, 0, 1000)
    np.testing.assert_allclose(pg.project([[100, 0, 0], [0, 100, 0]], io, eo), [[10, 0], [0, 10]])


def test_behind_camera_is_raised_or_flagged():
    io, eo = aerial()
    M = eo.matrix
    # two points behind the camera (along +m3; beside the principal plane)
    pts = np.array([GROUND, eo.position + 100 * M[2], eo.position + 100 * M[0] + M[2]])
    with pytest.raises(DegenerateGeometryError, match=r"2 point\(s\) lie behind the camera"):
        pg.project(pts, io, eo)
    out = pg.project(pts, io, eo, behind="nan")
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1:]))
    np.testing.assert_array_equal(pg.in_front(pts, eo), [True, False, False])
    with pytest.raises(InputError):
        pg.project(pts, io, eo, behind="ignore")


def test_bad_inputs():
    io, eo = aerial()
    with pytest.raises(InputError, match="NaN"):
        pg.project([[1, 2, np.nan]], io, eo)
    with pytest.raises(InputError, match="shape"):
        pg.project([[1, 2]], io, eo)
    with pytest.raises(InputError, match="f must be > 0"):
        pg.InteriorOrientation(-1)
    with pytest.raises(InputError, match="unit"):
        pg.InteriorOrientation(1, unit="inch")
    with pytest.raises(InputError, match="NaN"):
        pg.ExteriorOrientation(0, 0, np.nan)
    with pytest.raises(InputError, match="pixel geometry"):
        io.image_to_pixel([0, 0])
    with pytest.raises(InputError, match="pixel_size"):
        pg.InteriorOrientation.digital(100, 0, 0, unit="mm")


def test_image_variant_interior_orientation():
    io, eo = aerial()
    var = pg.ImageVariantInteriorOrientation(io, {"img2": (0.01, -0.02, 0.05)})
    io2 = var.for_image("img2")
    assert io2.x0 == pytest.approx(0.018) and io2.y0 == pytest.approx(-0.14)
    assert io2.f == pytest.approx(152.19)
    assert var.for_image("img1") == io
    # a change of the principal point shifts every image point by the same amount
    d = pg.project(GROUND, io2, eo) - pg.project(GROUND, io.for_image(0, 0, 0.05), eo)
    np.testing.assert_allclose(d, [0.01, -0.02], atol=1e-12)
    with pytest.raises(InputError, match="three"):
        pg.ImageVariantInteriorOrientation(io, {"a": (1, 2)})


def test_serialisation_round_trip():
    io = pg.InteriorOrientation.digital(
        3000.0,
        2000.0,
        1500.0,
        fy=2990.0,
        b2=0.3,
        distortion=pg.BrownDistortion(k1=-0.1, p2=1e-4),
        image_size=(4000, 3000),
    )
    assert pg.InteriorOrientation.from_dict(io.to_dict()) == io
    eo = pg.ExteriorOrientation.from_degrees(1, 2, 3, 10, -20, 200)
    back = pg.ExteriorOrientation.from_dict(eo.to_dict("gon"))
    np.testing.assert_allclose(back.parameters, eo.parameters, atol=1e-12)
    cam = pg.FrameCamera(io, eo)
    assert pg.FrameCamera.from_dict(cam.to_dict()).interior == io


def _random_camera(draw_angles, rng):
    io = pg.InteriorOrientation(
        100.0,
        0.1,
        -0.2,
        b1=0.05,
        b2=0.02,
        distortion=pg.BrownDistortion(-0.08, 0.03, -0.004, 0.0002, 1e-4, -2e-4),
    )
    eo = pg.ExteriorOrientation(*rng.uniform(-100, 100, 3), *draw_angles)
    return io, eo


@settings(max_examples=40, deadline=None)
@given(
    st.floats(-np.pi, np.pi),
    st.floats(-1.4, 1.4),
    st.floats(-np.pi, np.pi),
    st.integers(0, 2**31 - 1),
)
def test_ray_and_height_invert_projection(omega, phi, kappa, seed):
    rng = np.random.default_rng(seed)
    io, eo = _random_camera((omega, phi, kappa), rng)
    # points in front of the camera: random image positions and depths
    xn = rng.uniform(-0.4, 0.4, (50, 2))
    depth = rng.uniform(10, 500, 50)
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(50)]) * depth[:, None]
    ground = eo.position + pc @ eo.matrix
    xy = pg.project(ground, io, eo)
    C, d = pg.image_rays(xy, io, eo)
    # every ground point lies on its ray, in front of the centre
    rel = ground - C
    t = np.sum(rel * d, axis=1)
    assert np.all(t > 0)
    np.testing.assert_allclose(rel - t[:, None] * d, 0, atol=1e-7)
    # the point at its own height is the ground point, unless the ray is nearly horizontal
    steep = np.abs(d[:, 2]) > 0.05
    back = pg.ground_at_height(xy[steep], io, eo, ground[steep, 2])
    np.testing.assert_allclose(back, ground[steep], atol=1e-6)


def test_ground_at_height_behind():
    io, eo = aerial()
    xy = pg.project(GROUND, io, eo)[None]
    with pytest.raises(DegenerateGeometryError, match="height plane"):
        pg.ground_at_height(xy, io, eo, 5000.0)
    assert np.all(np.isnan(pg.ground_at_height(xy, io, eo, 5000.0, behind="nan")))


def test_analytic_derivatives_match_central_differences():
    rng = np.random.default_rng(3)
    io, eo = _random_camera(np.radians([20.0, -15.0, 130.0]), rng)
    xn = rng.uniform(-0.4, 0.4, (30, 2))
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(30)]) * rng.uniform(50, 200, (30, 1))
    g = eo.position + pc @ eo.matrix
    names = ("f", "x0", "y0", "b1", "b2", "k1", "k2", "k3", "k4", "p1", "p2")
    D = projection_derivatives(g, io, eo, names)
    np.testing.assert_allclose(D.xy, pg.project(g, io, eo), atol=1e-12)

    def num(fun, h):
        return (fun(h) - fun(-h)) / (2 * h)

    p = eo.parameters
    for j in range(6):
        h = 1e-4 if j < 3 else 1e-7

        def f_eo(dh, j=j):
            q = p.copy()
            q[j] += dh
            return pg.project(g, io, pg.ExteriorOrientation(*q))

        np.testing.assert_allclose(D.d_eo[:, :, j], num(f_eo, h), rtol=1e-5, atol=1e-6)
    for j, name in enumerate(names):

        def f_io(dh, name=name):
            if name in ("f", "x0", "y0", "b1", "b2"):
                io2 = dataclasses.replace(io, **{name: getattr(io, name) + dh})
            else:
                dist = dataclasses.replace(
                    io.distortion, **{name: getattr(io.distortion, name) + dh}
                )
                io2 = io.with_distortion(dist)
            return pg.project(g, io2, eo)

        np.testing.assert_allclose(D.d_io[:, :, j], num(f_io, 1e-6), rtol=1e-5, atol=1e-6)

    def f_g(dh, k):
        gg = g.copy()
        gg[:, k] += dh
        return pg.project(gg, io, eo)

    for k in range(3):
        np.testing.assert_allclose(
            D.d_ground[:, :, k], num(lambda h, k=k: f_g(h, k), 1e-4), rtol=1e-5, atol=1e-7
        )
