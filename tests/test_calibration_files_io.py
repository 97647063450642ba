"""Calibrations of other tools read where photogeom expects a calibration.

Before: an OpenCV ``cv2.FileStorage`` calibration (YAML or XML) was written but not read
("an OpenCV YAML is written, not read"), and a COLMAP ``cameras.txt`` of one camera was
neither read nor written by ``pg.read_calibration`` / ``pg.write_calibration``, ``camera
convert`` (``TARGET b.txt: the suffix names the format``) or ``--calibration`` (Metashape XML
only). Now both are read (format by content) and written (``.yaml``/``.yml``, ``.txt``),
converted exactly or refused naming the terms that have no Brown equivalent.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg

cv2 = pytest.importorskip("cv2")

K = np.array([[1002.5, 0.0, 641.3], [0.0, 998.75, 479.2], [0.0, 0.0, 1.0]])
DIST5 = np.array([0.1, -0.05, 0.001, -0.002, 0.01])
SIZE = (1280, 960)
X = np.random.default_rng(11).uniform([-0.4, -0.3, 1.0], [0.4, 0.3, 3.0], (40, 3))


def _write_fs(path, dist, *, size=SIZE, K=K, **extra):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    if size is not None:
        fs.write("image_width", size[0])
        fs.write("image_height", size[1])
    for key, value in extra.items():
        fs.write(key, value)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", np.asarray(dist, dtype=float))
    fs.release()


def _cv_project(K, dist):
    uv, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, np.asarray(dist, dtype=float))
    return uv.reshape(-1, 2)


# --- OpenCV ------------------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".yml", ".xml"])
@pytest.mark.parametrize("n", [4, 5, 8, 12, 14])
def test_opencv_filestorage_projects_as_cv2(tmp_path, suffix, n):
    dist = np.zeros(n)
    dist[: min(n, 5)] = DIST5[: min(n, 5)]
    path = tmp_path / f"cam{suffix}"
    _write_fs(path, dist.reshape(-1, 1) if n % 2 else dist.reshape(1, -1))
    cal = pg.read_calibration(path)
    assert (cal.width, cal.height) == SIZE
    assert cal.f == K[1, 1] and cal.b1 == K[0, 0] - K[1, 1]  # fx != fy kept as b1
    assert (cal.p1, cal.p2) == (dist[3], dist[2])  # OpenCV's p1, p2 are Metashape's p2, p1
    uv = cal.project_camera(X)  # photogeom's pixel origin: the top-left pixel's centre
    np.testing.assert_allclose(uv, _cv_project(K, dist), rtol=0, atol=1e-9)


def test_opencv_sample_file_is_read(tmp_path):
    """What OpenCV's camera_calibration sample writes (OpenCV 4's ``%YAML:1.0``, strings,
    per-view errors and extrinsics besides the calibration)."""
    path = tmp_path / "out_camera_data.yml"
    path.write_text(
        "%YAML:1.0\n---\n"
        'calibration_time: "Tue 24 Nov 2026 10:00:00 UTC"\n'
        "nr_of_frames: 25\nimage_width: 1280\nimage_height: 960\nboard_width: 9\n"
        "board_height: 6\nsquare_size: 50.\nfix_aspect_ratio: 1.\nflags: 14\n"
        "fisheye_model: 0\n"
        "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 1.0025e+03, 0., 6.413e+02, 0., 9.9875e+02, 4.792e+02, 0., 0.,\n"
        "       1. ]\n"
        "distortion_coefficients: !!opencv-matrix\n   rows: 5\n   cols: 1\n   dt: d\n"
        "   data: [ 1.0000000000000001e-01, -5.0000000000000003e-02, 1.e-03,\n"
        "       -2.e-03, 1.0000000000000000e-02 ]\n"
        "avg_reprojection_error: 2.1e-01\n"
        "per_view_reprojection_errors: !!opencv-matrix\n   rows: 2\n   cols: 1\n   dt: f\n"
        "   data: [ 2.0e-01, 2.2e-01 ]\n"
    )
    cal = pg.read_calibration(path)
    np.testing.assert_allclose(cal.project_camera(X), _cv_project(K, DIST5), rtol=0, atol=1e-9)


def test_opencv_read_write_round_trip_is_exact(tmp_path):
    """An OpenCV file read and written again holds the same numbers to the last bit; a
    photogeom calibration written and read again projects the same (b1 = fx - fy and the
    absolute principal point cost at most an ulp of fx and of w/2)."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        w, h = int(rng.integers(200, 9000)), int(rng.integers(200, 9000))
        fy = float(rng.uniform(0.5, 2) * w)
        Kk = np.array(
            [
                [fy + rng.normal(0, 2), 0, w / 2 - 0.5 + rng.normal(0, 30)],
                [0, fy, h / 2 - 0.5 + rng.normal(0, 30)],
                [0, 0, 1],
            ]
        )
        dist = rng.normal(0, 0.01, 5)
        _write_fs(tmp_path / "src.yml", dist, size=(w, h), K=Kk)
        cal = pg.read_calibration(tmp_path / "src.yml")
        pg.write_calibration(cal, tmp_path / "out.yaml")
        fs = cv2.FileStorage(str(tmp_path / "out.yaml"), cv2.FILE_STORAGE_READ)
        K2 = fs.getNode("camera_matrix").mat()
        d2 = fs.getNode("distortion_coefficients").mat().ravel()
        fs.release()
        np.testing.assert_array_equal(K2, Kk)
        np.testing.assert_array_equal(d2, dist)
        assert pg.read_calibration(tmp_path / "out.yaml") == cal
        for suffix in (".yaml", ".txt"):
            pg.write_calibration(cal, tmp_path / f"c{suffix}")
            assert pg.read_calibration(tmp_path / f"c{suffix}") == cal, suffix
        back = dict(
            f=cal.f, cx=cal.cx + 1e-9, cy=cal.cy, k1=cal.k1, k2=cal.k2, k3=cal.k3, p1=cal.p1,
            p2=cal.p2, b1=cal.b1 + 1e-9,
        )  # fmt: skip
        shifted = pg.MetashapeCalibration(w, h, **back)
        pg.write_calibration(shifted, tmp_path / "s.txt")
        again = pg.read_calibration(tmp_path / "s.txt")
        assert abs(again.b1 - shifted.b1) <= np.spacing(shifted.f + shifted.b1)
        assert abs(again.cx - shifted.cx) <= np.spacing(w / 2.0)
        np.testing.assert_allclose(
            again.project_camera(X), shifted.project_camera(X), rtol=0, atol=1e-9
        )


def test_opencv_std_deviations_are_read(tmp_path):
    from photogeom.camera.calibration_files import read_calibration_file

    base = pg.MetashapeCalibration(*SIZE, 1000.0, cx=3.0, k1=0.1, p1=1e-3, p2=2e-3)
    names = ("f", "cx", "cy", "k1", "p1", "p2")
    cov = np.diag([4.0, 1.0, 2.25, 1e-6, 1e-8, 4e-8])
    pg.write_calibration(base, tmp_path / "c.yaml", covariance=(names, cov))
    got, std, _ = read_calibration_file(tmp_path / "c.yaml")
    assert got == base
    assert std == pytest.approx(dict(zip(names, np.sqrt(np.diag(cov)))), rel=1e-15)


@pytest.mark.parametrize(
    ("dist", "named"),
    [
        ([0.1, 0, 0, 0, 0, 0.2, 0, 0], "k4 = 0.2"),
        ([0.1, 0, 0, 0, 0, 0, 0, 0.3], "k6 = 0.3"),
        ([0.1, 0, 0, 0, 0, 0, 0, 0, 0.01, 0, 0, 0], "s1 = 0.01"),
        ([0.1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0.02], "ty = 0.02"),
    ],
)
def test_opencv_terms_without_brown_equivalent_are_named(tmp_path, dist, named):
    _write_fs(tmp_path / "c.yml", dist)
    with pytest.raises(pg.FileFormatError, match=named):
        pg.read_calibration(tmp_path / "c.yml")


def test_opencv_refusals(tmp_path):
    _write_fs(tmp_path / "fish.yml", DIST5[:4], fisheye_model=1)
    with pytest.raises(pg.FileFormatError, match="fisheye"):
        pg.read_calibration(tmp_path / "fish.yml")
    skew = K.copy()
    skew[0, 1] = 0.5
    _write_fs(tmp_path / "skew.yml", DIST5, K=skew)
    with pytest.raises(pg.FileFormatError, match="skew"):
        pg.read_calibration(tmp_path / "skew.yml")
    K22 = K.copy()
    K22[2, 2] = 2.0
    _write_fs(tmp_path / "k22.yml", DIST5, K=K22)
    with pytest.raises(pg.FileFormatError, match=r"got rows .* below the first"):
        pg.read_calibration(tmp_path / "k22.yml")
    text = (tmp_path / "k22.yml").read_text().replace("image_width: 1280", "image_width: .inf")
    (tmp_path / "inf.yml").write_text(text)
    with pytest.raises(pg.FileFormatError, match="not whole pixels"):  # was an OverflowError
        pg.read_calibration(tmp_path / "inf.yml")
    _write_fs(tmp_path / "six.yml", np.zeros(6))
    with pytest.raises(pg.FileFormatError, match="6 terms"):
        pg.read_calibration(tmp_path / "six.yml")
    (tmp_path / "bad.yml").write_text("%YAML:1.0\n---\ncamera_matrix: [ 1, \n")
    with pytest.raises(pg.FileFormatError, match="OpenCV FileStorage"):
        pg.read_calibration(tmp_path / "bad.yml")
    _write_fs(tmp_path / "nosize.yml", DIST5, size=None)
    with pytest.raises(pg.FileFormatError, match="image_width"):
        pg.read_calibration(tmp_path / "nosize.yml")
    from photogeom.camera.calibration_files import read_calibration_file

    cal, _, _ = read_calibration_file(tmp_path / "nosize.yml", SIZE)
    _write_fs(tmp_path / "size.yml", DIST5)
    assert cal == pg.read_calibration(tmp_path / "size.yml")
    with pytest.raises(pg.InputError, match="leave the image size out"):
        read_calibration_file(tmp_path / "size.yml", SIZE)


# --- COLMAP ------------------------------------------------------------------------------------

COLMAP_CAMERAS = {
    "SIMPLE_PINHOLE": [1000.0, 640.5, 480.25],
    "PINHOLE": [1002.5, 998.75, 641.3, 479.2],
    "SIMPLE_RADIAL": [1000.0, 640.5, 480.25, -0.12],
    "RADIAL": [1000.0, 640.5, 480.25, -0.12, 0.03],
    "OPENCV": [1002.5, 998.75, 641.3, 479.2, -0.12, 0.03, 1e-3, -2e-3],
    "FULL_OPENCV": [1002.5, 998.75, 641.3, 479.2, -0.12, 0.03, 1e-3, -2e-3, 0.01, 0, 0, 0],
}


def _colmap_formulas(model, params):
    """COLMAP's projection by the formulas of its documentation (corner pixel origin)."""
    q = list(params)
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        fx = fy = q[0]
        cx, cy = q[1], q[2]
        k1, k2 = [*q[3:], 0.0, 0.0][:2]
        k3 = p1 = p2 = 0.0
    else:
        fx, fy, cx, cy = q[:4]
        k1, k2, p1, p2, k3 = [*q[4:], 0.0, 0.0, 0.0, 0.0, 0.0][:5]
    x, y = X[:, 0] / X[:, 2], X[:, 1] / X[:, 2]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([fx * xd + cx, fy * yd + cy])


def _colmap_references(model, params):
    """COLMAP's projection: its documented formulas and, when installed, pycolmap's."""
    refs = [_colmap_formulas(model, params)]
    try:
        import pycolmap
    except ImportError:  # pragma: no cover - pycolmap is optional
        return refs
    cam = pycolmap.Camera(model=model, width=SIZE[0], height=SIZE[1], params=params)
    refs.append(np.asarray(cam.img_from_cam(X)))
    return refs


@pytest.mark.parametrize("model", list(COLMAP_CAMERAS))
def test_colmap_camera_projects_as_colmap(tmp_path, model):
    params = COLMAP_CAMERAS[model]
    path = tmp_path / "cameras.txt"
    path.write_text(
        "# Camera list with one line of data per camera:\n"
        f"7 {model} {SIZE[0]} {SIZE[1]} {' '.join(map(repr, params))}\n"
    )
    cal = pg.read_calibration(path)
    uv = cal.project_camera(X, pixel_origin="corner")  # COLMAP's origin: the image corner
    for ref in _colmap_references(model, params):
        np.testing.assert_allclose(uv, ref, rtol=0, atol=1e-9)
    pg.write_calibration(cal, tmp_path / "back.txt")
    line = (tmp_path / "back.txt").read_text().splitlines()[-1].split()
    assert line[:4] == ["1", model, str(SIZE[0]), str(SIZE[1])]
    assert [float(v) for v in line[4:]] == params  # to the last bit


def test_colmap_refusals(tmp_path):
    p = tmp_path / "cameras.txt"
    p.write_text("1 FULL_OPENCV 100 80 90 90 50 40 0 0 0 0 0 0.5 0 0\n")
    with pytest.raises(pg.FileFormatError, match="k4, k5, k6"):
        pg.read_calibration(p)
    p.write_text("1 OPENCV_FISHEYE 100 80 90 90 50 40 0 0 0 0\n")
    with pytest.raises(pg.FileFormatError, match="OPENCV_FISHEYE"):
        pg.read_calibration(p)
    p.write_text("1 PINHOLE 100 80 90 90 50 40\n2 PINHOLE 100 80 90 90 50 40\n")
    with pytest.raises(pg.FileFormatError, match="2 cameras"):
        pg.read_calibration(p)
    with pytest.raises(pg.InputError, match="K4"):
        pg.write_calibration(pg.MetashapeCalibration(100, 80, 90.0, k4=0.1), tmp_path / "c.txt")
    assert not (tmp_path / "c.txt").exists()


# --- command line ------------------------------------------------------------------------------


def test_cli_convert_and_calibration_options(cli, tmp_path):
    _write_fs(tmp_path / "cam.yml", DIST5)
    code, _, err = cli("camera", "convert", tmp_path / "cam.yml", tmp_path / "cam.txt")
    assert code == 0, err
    code, _, err = cli("camera", "convert", tmp_path / "cam.txt", tmp_path / "cam.xml")
    assert code == 0, err
    ref = pg.read_calibration(tmp_path / "cam.yml")
    assert pg.read_metashape_xml(tmp_path / "cam.xml") == pg.read_calibration(tmp_path / "cam.txt")
    np.testing.assert_allclose(
        pg.read_calibration(tmp_path / "cam.xml").project_camera(X), ref.project_camera(X),
        rtol=0, atol=1e-9,
    )
    code, _, err = cli(
        "camera", "convert", tmp_path / "cam.yml", tmp_path / "x.xml", "--image-size", "4,3"
    )
    assert code == 2 and "--image-size" in err and "image_width" in err
    pts = tmp_path / "pts.csv"
    pts.write_text("id,X,Y,Z\na,10,20,0\nb,-30,5,3\n")
    outs = []
    for opt in (
        ["--calibration", tmp_path / "cam.xml"],
        ["--calibration", tmp_path / "cam.yml"],
        ["--calibration", tmp_path / "cam.txt"],
        ["--camera", tmp_path / "cam.yml"],
        ["--camera", tmp_path / "cam.txt"],
    ):
        code, out, err = cli("camera", "project", pts, *opt, "--eo", "0,0,100,1,2,3", "--pixel")
        assert code == 0, (opt, err)
        outs.append(out)
    assert len(set(outs)) == 1
    (tmp_path / "fish.yml").write_text(
        (tmp_path / "cam.yml").read_text().replace("image_width", "fisheye_model: 1\nimage_width")
    )
    code, _, err = cli(
        "camera", "project", pts, "--calibration", tmp_path / "fish.yml", "--eo", "0,0,100,0,0,0"
    )
    assert code == 2 and "--calibration" in err and "fisheye" in err


def test_bundle_adjust_writes_a_colmap_camera(cli, tmp_path):
    block = tmp_path / "block"
    small = ["--strips", "2", "--images-per-strip", "4", "--tie-points-per-image", "40"]
    code, _, err = cli("bundle", "simulate", block, "--seed", "3", *small)
    assert code == 0, err
    code, _, err = cli(
        "bundle", "adjust", block, "--free", "f,b2", "--output-calibration", tmp_path / "c.txt"
    )
    assert code == 2 and "COLMAP" in err and "B2" in err and not (tmp_path / "c.txt").exists()
    code, _, err = cli(
        "bundle", "adjust", block, "--free", "f,cx,cy,k1,k2,p1,p2,b1",
        "--output-calibration", tmp_path / "c.txt",
    )  # fmt: skip
    assert code == 0, err
    line = (tmp_path / "c.txt").read_text().splitlines()[-1].split()
    assert line[1] == "OPENCV"  # the smallest model holding b1, k1, k2, p1, p2
    code, _, err = cli(
        "bundle", "adjust", block, "--free", "f,cx,cy,k1,k2,p1,p2,b1",
        "--output-calibration", tmp_path / "c.xml",
    )  # fmt: skip
    assert code == 0, err
    xml = pg.read_metashape_xml(tmp_path / "c.xml")
    txt = pg.read_calibration(tmp_path / "c.txt")
    np.testing.assert_allclose(
        txt.project_camera(X), xml.project_camera(X), rtol=0, atol=1e-9
    )


def test_opencv_json_and_yaml_without_header(tmp_path):
    """cv2.FileStorage's JSON (before: 'no calibration found (expected calibration or
    interior...)') and a hand-written FileStorage YAML without its %YAML line (before: 'not a
    calibration file photogeom reads') are OpenCV calibrations too."""
    _write_fs(tmp_path / "cv.json", DIST5)
    cal = pg.read_calibration(tmp_path / "cv.json")
    np.testing.assert_allclose(cal.project_camera(X), _cv_project(K, DIST5), rtol=0, atol=1e-9)
    (tmp_path / "bare.yml").write_text(
        "image_width: 1280\nimage_height: 960\ncamera_matrix: !!opencv-matrix\n  rows: 3\n"
        "  cols: 3\n  dt: d\n  data: [1002.5, 0, 641.3, 0, 998.75, 479.2, 0, 0, 1]\n"
        "dist_coeffs: [0.1, -0.05, 0.001, -0.002, 0.01]\n"
    )
    assert pg.read_calibration(tmp_path / "bare.yml") == cal


def test_intersection_names_what_a_calibration_lacks(cli, tmp_path):
    """Before: 'cam.yml: not valid JSON' (the CRS look-up read every --camera as JSON)."""
    _write_fs(tmp_path / "cam.yml", DIST5)
    for k in (1, 2):
        (tmp_path / f"i{k}.csv").write_text("id,x,y\na,1,2\n")
    code, _, err = cli(
        "orient", "intersection", tmp_path / "i1.csv", tmp_path / "i2.csv",
        "--camera", tmp_path / "cam.yml", "--camera", tmp_path / "cam.yml",
    )  # fmt: skip
    assert code == 2 and "interior only" in err and "exterior" in err
