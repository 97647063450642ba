"""Image coordinate systems: pixel <-> image (mm), fiducial -> image centre, handedness."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom import imagecoords as ic
from photogeom.errors import InputError


def test_lecture_example_6_fiducial_to_image_centre():
    # fiducial point (83.106, 63.466) mm, principal point (0.012, -0.008), f = 152 mm
    out = ic.fiducial_to_image((83.106, 63.466), (0.012, -0.008), 152.0)
    np.testing.assert_allclose(out, (83.094, 63.474, -152.0), atol=5e-4)
    # the slide prints 83.94 for x: a typo (83.106 - 0.012 = 83.094)
    assert abs(out[0] - 83.94) > 0.8
    back = ic.image_to_fiducial(out, (0.012, -0.008))
    np.testing.assert_allclose(back, (83.106, 63.466), atol=1e-12)


def test_lecture_example_7_pixel_to_image():
    # pixel (row 9541, col 356), principal point (row 6912, col 3840), 12 um pixels, f = 120 mm
    out = ic.pixel_to_image((356, 9541), pixel_size=0.012, principal_point=(3840, 6912),
                            focal_length=120.0)
    np.testing.assert_allclose(out, (-41.808, -31.548, -120.0), atol=5e-4)
    back = ic.image_to_pixel(out, pixel_size=0.012, principal_point=(3840, 6912),
                             focal_length=120.0)
    np.testing.assert_allclose(back, (356, 9541), atol=1e-9)


def test_formulas_and_sign_of_y():
    # x = d (col - col_pp), y = -d (row - row_pp): a pixel below the principal point has y < 0
    sys_ = ic.PixelSystem(pixel_size=(0.01, 0.02), principal_point=(100, 50))
    out = sys_.to_image([[110, 50], [100, 60], [90, 40]])
    np.testing.assert_allclose(out, [[0.1, 0.0], [0.0, -0.2], [-0.1, 0.2]], atol=1e-15)
    # right-handed result: the pixel system's (right, down) becomes (x, y) with y up,
    # so a counter-clockwise triangle in the image is clockwise in pixels
    tri_px = np.array([[0, 0], [10, 0], [0, 10]], float)  # right, then down
    tri_mm = sys_.to_image(tri_px)
    def cross(t):
        a, b = t[1] - t[0], t[2] - t[0]
        return a[0] * b[1] - a[1] * b[0]

    cross_px, cross_mm = cross(tri_px), cross(tri_mm)
    assert np.sign(cross_px) == -np.sign(cross_mm)


def test_pixel_origin_conventions():
    # a 4 x 2 image: centre convention (1.5, 0.5), corner convention (2, 1)
    np.testing.assert_allclose(ic.image_center((4, 2), "center"), (1.5, 0.5))
    np.testing.assert_allclose(ic.image_center((4, 2), "corner"), (2.0, 1.0))
    np.testing.assert_allclose(ic.convert_pixel_origin((0, 0), "center", "corner"), (0.5, 0.5))
    np.testing.assert_allclose(ic.convert_pixel_origin((0.5, 0.5), "corner", "center"), (0, 0))
    # the same physical point gives the same image coordinates in both conventions
    c = ic.PixelSystem.centered((4000, 3000), 0.005, focal_length=35.0, origin="center")
    k = c.with_origin("corner")
    assert k.origin == "corner"
    np.testing.assert_allclose(k.principal_point, ic.image_center((4000, 3000), "corner"))
    p_center = np.array([[0.0, 0.0], [3999.0, 2999.0], [12.25, 40.5]])
    p_corner = ic.convert_pixel_origin(p_center, "center", "corner")
    np.testing.assert_allclose(c.to_image(p_center), k.to_image(p_corner), atol=1e-12)
    # the image centre maps to (0, 0, -f)
    np.testing.assert_allclose(c.to_image(c.principal_point), (0, 0, -35.0), atol=1e-12)
    with pytest.raises(InputError, match="origin"):
        ic.PixelSystem(0.005, (1, 1), origin="middle")


@settings(max_examples=40, deadline=None)
@given(
    dx=st.floats(1e-4, 0.1), dy=st.floats(1e-4, 0.1),
    cpp=st.floats(-100, 10000), rpp=st.floats(-100, 10000),
    f=st.floats(1.0, 500.0), origin=st.sampled_from(["center", "corner"]),
)
def test_pixel_image_round_trip(dx, dy, cpp, rpp, f, origin):
    rng = np.random.default_rng(1)
    px = rng.uniform(0, 10000, (20, 2))
    sys_ = ic.PixelSystem((dx, dy), (cpp, rpp), f, origin)
    mm = sys_.to_image(px)
    assert mm.shape == (20, 3)
    np.testing.assert_allclose(mm[:, 2], -f)
    np.testing.assert_allclose(sys_.to_pixel(mm), px, rtol=0, atol=1e-9 * 10000)
    np.testing.assert_allclose(sys_.to_pixel(mm[:, :2]), px, rtol=0, atol=1e-9 * 10000)


def test_bad_inputs():
    with pytest.raises(InputError, match="pixel_size"):
        ic.pixel_to_image((1, 2), pixel_size=0, principal_point=(0, 0))
    with pytest.raises(InputError, match="NaN"):
        ic.pixel_to_image([[1, np.nan]], pixel_size=0.01, principal_point=(0, 0))
    with pytest.raises(InputError, match="shape"):
        ic.pixel_to_image([[1, 2, 3]], pixel_size=0.01, principal_point=(0, 0))
    with pytest.raises(InputError, match="focal"):
        ic.fiducial_to_image((1, 2), (0, 0), -5)
    sys_ = ic.PixelSystem(0.01, (0, 0), focal_length=100.0)
    with pytest.raises(InputError, match="-f"):
        sys_.to_pixel([[1.0, 2.0, -90.0]])


def test_handedness_plan():
    assert ic.handedness("pixel") == "left"
    assert ic.handedness("Image") == "right"
    with pytest.raises(InputError, match="unknown coordinate system"):
        ic.handedness("screen")
    none = ic.handedness_plan(None, None)
    assert not none.flip_source and not none.flip_target
    same = ic.handedness_plan("pixel", "pixel")
    assert not same.flip_source and not same.flip_target
    plan = ic.handedness_plan("pixel", "image")
    assert plan.flip_source and not plan.flip_target and "left-handed" in plan.note
    plan = ic.handedness_plan("fiducial", "pixel")
    assert plan.flip_target and not plan.flip_source
    with pytest.raises(InputError, match="both"):
        ic.handedness_plan("pixel", None)
    np.testing.assert_array_equal(ic.flip_y([[1.0, 2.0], [3.0, -4.0]]), [[1, -2], [3, 4]])
