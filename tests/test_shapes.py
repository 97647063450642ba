"""One shape rule for every public function of points (docs/conventions.md, "Arrays of
points"): (n, k) in gives n rows out, (0, k) none, one point (k,) one result without the
point axis, a list as the array; any other shape is refused, not reshaped.

Before, ``image_rays``, ``ground_at_height``, a residual grid's ``evaluate`` / ``correct``,
``correct_points``, ``calibration.correct_observations`` (of arrays), ``sim.local_field``,
``InteriorOrientation.image_from_normalized`` / ``normalized_from_image``,
``MetashapeCalibration.project_normalized`` / ``project_camera`` / ``distort_pixels``,
``BrownDistortion.jacobian`` / ``coefficient_jacobian`` and ``camera.measured_to_fiducial``
returned (1, ...) for one point (``project`` and ``apply`` gave (k,)), ``in_front`` gave
(1,); and the functions that reshaped their input to (-1, 2) read a transposed (2, 3) array
or a flat list of four numbers as points (``ExteriorOrientation.to_camera`` raised numpy's
broadcasting ValueError); ``crs.transform_points`` and ``crs.points_between`` refused one
point.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import fit_grid
from photogeom.calibration.correction import correct_points
from photogeom.camera.metashape import MetashapeCalibration
from photogeom.errors import InputError

IO = pg.InteriorOrientation.digital(
    f=35.0, pixel_size=0.005, col_pp=2000, row_pp=1500, image_size=(4000, 3000)
)
IOD = IO.with_distortion(pg.BrownDistortion(k1=0.01, p1=1e-4))
EO = pg.ExteriorOrientation(0.0, 0.0, 100.0, 0.01, -0.02, 0.3)
BROWN = pg.BrownDistortion(k1=0.01, k2=-0.001, p2=2e-4)
MS = MetashapeCalibration(width=4000, height=3000, f=3500.0, k1=-0.05)
CAM = pg.FrameCamera(IO, EO)

GROUND = np.array([[1.0, 2.0, 0.0], [10.0, -5.0, 1.0], [0.0, 0.0, 2.0]])
IMAGE_MM = np.array([[1.0, 2.0], [-3.0, 1.5], [0.5, -0.5]])
PIXELS = np.array([[100.0, 200.0], [1000.0, 1500.0], [3000.0, 2000.0]])
NORMALISED = np.array([[0.1, 0.2], [-0.1, 0.05], [0.0, 0.0]])
CAMERA_FRAME = np.array([[0.1, 0.2, 1.0], [0.0, 0.1, 2.0], [0.3, 0.2, 1.5]])
GEOGRAPHIC = np.array([[11.0, 48.0, 500.0], [11.1, 48.1, 600.0], [10.9, 47.9, 400.0]])
ECEF = np.array([[4.2e6, 8.1e5, 4.7e6], [4.1e6, 8.2e5, 4.8e6], [4.3e6, 8.0e5, 4.6e6]])
GRID_UV = np.array([[100.0, 200.0], [1000.0, 700.0], [500.0, 500.0]])


def _grid():
    rng = np.random.default_rng(3)
    uv = np.column_stack([rng.uniform(0, 1599, 400), rng.uniform(0, 999, 400)])
    res = np.column_stack([np.sin(uv[:, 0] / 500), np.cos(uv[:, 1] / 300)])
    return fit_grid(uv, res, (1600, 1000), 200, folds=0)


GRID = _grid()


def _sim():
    return pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3)


SIM = _sim()
_AFFINE_GROUND = np.random.default_rng(5).normal(size=(10, 3)) * [50.0, 50.0, 5.0]
AFFINE = pg.estimate_affine_camera(_AFFINE_GROUND, pg.project(_AFFINE_GROUND, IO, EO)).model
FIDUCIALS = pg.fit_fiducials(
    np.array([[0.0, 0.0], [4000.0, 0.0], [4000.0, 3000.0], [0.0, 3000.0]]),
    np.array([[-10.0, 7.5], [10.0, 7.5], [10.0, -7.5], [-10.0, -7.5]]),
)
IMAGE = sorted(SIM.block.images)[0]

#: name -> (function of the points, points (n = 3), shape of one result)
FUNCTIONS = {
    "Similarity3D.apply": (
        pg.Similarity3D(2.0, pg.opk_matrix(0.1, 0.2, 0.3), [1.0, 2.0, 3.0]).apply,
        GROUND,
        (3,),
    ),
    "Affine2D.apply": (pg.Affine2D(1.0, 0.1, 1.0, 0.0, 2.0, 2.0).apply, IMAGE_MM, (2,)),
    "project": (lambda p: pg.project(p, IO, EO), GROUND, (2,)),
    "project pixel": (lambda p: pg.project(p, IO, EO, system="pixel"), GROUND, (2,)),
    "in_front": (lambda p: pg.in_front(p, EO), GROUND, ()),
    "image_rays": (lambda p: pg.image_rays(p, IO, EO)[1], IMAGE_MM, (3,)),
    "ground_at_height": (lambda p: pg.ground_at_height(p, IO, EO, 0.0), IMAGE_MM, (3,)),
    "FrameCamera.project": (CAM.project, GROUND, (2,)),
    "FrameCamera.rays": (lambda p: CAM.rays(p)[1], IMAGE_MM, (3,)),
    "FrameCamera.ground_at_height": (lambda p: CAM.ground_at_height(p, 0.0), IMAGE_MM, (3,)),
    "DLT.project": (pg.DLT.from_matrix(pg.camera_matrix(IO, EO)).project, GROUND, (2,)),
    "InteriorOrientation.image_to_pixel": (IO.image_to_pixel, IMAGE_MM, (2,)),
    "InteriorOrientation.pixel_to_image": (IO.pixel_to_image, PIXELS, (2,)),
    "InteriorOrientation.image_from_normalized": (IOD.image_from_normalized, NORMALISED, (2,)),
    "InteriorOrientation.normalized_from_image": (IOD.normalized_from_image, IMAGE_MM, (2,)),
    "BrownDistortion.distort": (BROWN.distort, NORMALISED, (2,)),
    "BrownDistortion.jacobian": (BROWN.jacobian, NORMALISED, (2, 2)),
    "BrownDistortion.coefficient_jacobian": (
        lambda p: BROWN.coefficient_jacobian(p, ("k1", "p1")),
        NORMALISED,
        (2, 2),
    ),
    "MetashapeCalibration.project_normalized": (MS.project_normalized, NORMALISED, (2,)),
    "MetashapeCalibration.project_camera": (MS.project_camera, CAMERA_FRAME, (2,)),
    "MetashapeCalibration.distort_pixels": (MS.distort_pixels, PIXELS, (2,)),
    "ResidualGrid.evaluate": (GRID.evaluate, GRID_UV, (2,)),
    "ResidualGrid.correct": (GRID.correct, GRID_UV, (2,)),
    "correct_points": (lambda p: correct_points(p, GRID), GRID_UV, (2,)),
    "calibration.correct_observations": (
        lambda p: pg.calibration.correct_observations({7: p}, {7: GRID})[7],
        GRID_UV,
        (2,),
    ),
    "sim.local_field": (lambda p: SIM.local_field(IMAGE, p), GRID_UV, (2,)),
    "PixelSystem.to_image": (
        pg.imagecoords.PixelSystem(0.005, (2000, 1500)).to_image,
        PIXELS,
        (2,),
    ),
    "ExteriorOrientation.to_camera": (EO.to_camera, GROUND, (3,)),
    "crs.transform_points": (
        lambda p: pg.crs.transform_points(p, "EPSG:4979", "EPSG:4978"),
        GEOGRAPHIC,
        (3,),
    ),
    "crs.transform_points 2-D": (
        lambda p: pg.crs.transform_points(p, "EPSG:4326", "EPSG:32632"),
        GEOGRAPHIC[:, :2],
        (2,),
    ),
    "crs.points_between": (
        lambda p: pg.crs.points_between(p, "EPSG:4979", "EPSG:4978"),
        GEOGRAPHIC,
        (3,),
    ),
    "crs.ecef_to_enu": (lambda p: pg.crs.ecef_to_enu(p, 48.0, 11.0, 0.0), ECEF, (3,)),
    "AffineCamera.project": (AFFINE.project, GROUND, (2,)),
    "measured_to_fiducial": (
        lambda p: pg.camera.measured_to_fiducial(FIDUCIALS, p),
        PIXELS,
        (2,),
    ),
}

#: Functions returning a result object whose per-point arrays keep the point axis.
RESULTS = {
    "InteriorOrientation.undistort_image": (lambda p: IOD.undistort_image(p).points, IMAGE_MM),
    "BrownDistortion.undistort": (lambda p: BROWN.undistort(p).points, NORMALISED),
    "MetashapeCalibration.unproject": (lambda p: MS.unproject(p).points, PIXELS),
    "MetashapeCalibration.undistort_pixels": (lambda p: MS.undistort_pixels(p).points, PIXELS),
}


@pytest.mark.parametrize("name", sorted(FUNCTIONS))
def test_one_shape_rule(name):
    fn, points, one = FUNCTIONS[name]
    many = np.asarray(fn(points))
    assert many.shape == (3, *one)
    single = np.asarray(fn(points[1]))
    assert single.shape == one  # (k,) in: the point axis dropped
    np.testing.assert_allclose(single, many[1], rtol=1e-12, atol=1e-12)
    assert np.shape(fn(points[1:2])) == (1, *one)  # (1, k) stays (1, ...)
    assert np.shape(fn(points[:0])) == (0, *one)
    np.testing.assert_allclose(fn(points.tolist()), many, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(fn(points[1].tolist()), single, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", sorted(RESULTS))
def test_result_objects_keep_the_point_axis(name):
    fn, points = RESULTS[name]
    many = fn(points)
    assert many.shape == (3, 2)
    assert fn(points[1]).shape == (1, 2)
    np.testing.assert_allclose(fn(points[1]), many[1:2], rtol=1e-12, atol=1e-12)
    assert fn(points[:0]).shape == (0, 2)


def _two_column(name) -> bool:
    return FUNCTIONS[name][1].shape[1] == 2 if name in FUNCTIONS else True


#: Functions of 2-D or 3-D points: a transposed array is a valid array of the other kind.
EITHER_DIMENSION = ("crs.transform_points", "crs.transform_points 2-D")


@pytest.mark.parametrize(
    "name",
    sorted(n for n in FUNCTIONS if _two_column(n) and n not in EITHER_DIMENSION) + sorted(RESULTS),
)
def test_other_shapes_are_refused(name):
    fn, points = (FUNCTIONS[name][:2]) if name in FUNCTIONS else RESULTS[name]
    with pytest.raises(InputError, match=r"\(n, 2\)"):
        fn(points.T)  # three points transposed: (2, 3)
    with pytest.raises(InputError, match=r"\(n, 2\)"):
        fn(points[:2].ravel())  # a flat list of two points


def test_transposed_points_are_named():
    with pytest.raises(InputError, match="transpose"):
        MS.distort_pixels(PIXELS.T)


@pytest.mark.parametrize(
    "name", sorted(n for n in FUNCTIONS if not _two_column(n) and n not in EITHER_DIMENSION)
)
def test_other_shapes_of_3d_points_are_refused(name):
    fn, points = FUNCTIONS[name][:2]
    with pytest.raises(InputError, match=r"\(n, 3\)"):
        fn(points[:2].T)  # two points transposed: (3, 2)
    with pytest.raises(InputError, match=r"\(n, 3\)"):
        fn(points[:2].ravel())  # a flat list of two points
