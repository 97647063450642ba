"""``photogeom camera convert SOURCE TARGET``, a calibration between Metashape
XML, photogeom camera JSON and OpenCV YAML (before: ``No such command 'convert'``), and
``read_metashape_covariance`` (the ``<covariance>`` that ``read_metashape_xml`` ignores)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg
from photogeom.camera.calibration_files import read_metashape_covariance

CAL = pg.MetashapeCalibration(
    4000, 3000, 2800.123, cx=12.3, cy=-7.9, k1=-0.11, k2=0.05, k3=-0.01, p1=3e-4, p2=-2e-4,
    b1=1.7,
)
NAMES = ("f", "cx", "cy", "k1", "p1", "b1")
COV = np.diag([4.0, 1.0, 2.25, 1e-6, 1e-8, 0.09])
COV[0, 5] = COV[5, 0] = -0.3


def test_convert_keeps_calibration_and_covariance(cli, tmp_path):
    pg.write_calibration(CAL, tmp_path / "a.json", covariance=(NAMES, COV))
    code, _, err = cli("camera", "convert", tmp_path / "a.json", tmp_path / "b.xml")
    assert code == 0, err
    assert pg.read_metashape_xml(tmp_path / "b.xml", strict=True) == CAL
    names, C = read_metashape_covariance(tmp_path / "b.xml")
    idx = [NAMES.index(n) for n in names]
    np.testing.assert_array_equal(C, COV[np.ix_(idx, idx)])
    code, _, err = cli("camera", "convert", tmp_path / "b.xml", tmp_path / "c.json")
    assert code == 0, err
    a = json.loads((tmp_path / "a.json").read_text())
    c = json.loads((tmp_path / "c.json").read_text())
    assert c["calibration"] == a["calibration"] and c["std"] == a["std"]
    assert pg.read_calibration(tmp_path / "c.json") == CAL


def test_convert_to_opencv_projects_as_photogeom(cli, tmp_path):
    cv2 = pytest.importorskip("cv2")
    pg.write_calibration(CAL, tmp_path / "a.xml")
    code, _, err = cli("camera", "convert", tmp_path / "a.xml", tmp_path / "b.yml")
    assert code == 0, err
    fs = cv2.FileStorage(str(tmp_path / "b.yml"), cv2.FILE_STORAGE_READ)
    K, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    assert fs.getNode("std_deviations_intrinsics").empty()  # no covariance in a.xml
    fs.release()
    X = np.array([[1.0, 2.0, 10.0], [-3.0, 1.0, 9.0], [4.0, -2.5, 8.0]])
    uv, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, dist)
    np.testing.assert_allclose(uv[:, 0], CAL.project_camera(X), rtol=0, atol=1e-9)


def test_convert_a_resection_camera(cli, tmp_path):
    """An --output-params camera (interior in px inside model_parameters) converts; one
    without image size needs --image-size."""
    io = CAL.interior_orientation().to_dict()
    src = tmp_path / "cam.json"
    src.write_text(json.dumps({"model_parameters": {"interior": io}}))
    code, _, err = cli("camera", "convert", src, tmp_path / "cam.xml")
    assert code == 0, err
    back = pg.read_metashape_xml(tmp_path / "cam.xml")
    for name in ("f", "cx", "cy", "b1", "k1", "k2", "k3", "p1", "p2"):
        assert getattr(back, name) == pytest.approx(getattr(CAL, name), rel=1e-12, abs=1e-12)
    del io["image_size"]
    src.write_text(json.dumps({"interior": io}))
    code, _, err = cli("camera", "convert", src, tmp_path / "x.xml")
    assert code == 2 and "--image-size" in err
    code, _, err = cli(
        "camera", "convert", src, tmp_path / "x.xml", "--image-size", "4000,3000"
    )
    assert code == 0, err
    assert pg.read_metashape_xml(tmp_path / "x.xml") == back


def test_convert_image_size_as_the_other_commands_write_it(cli, tmp_path):
    """--image-size WIDTHxHEIGHT, as bundle adjust and grid fit take it (before: refused,
    'expected comma-separated numbers'); WIDTH,HEIGHT still read."""
    io = CAL.interior_orientation().to_dict()
    del io["image_size"]
    src = tmp_path / "cam.json"
    src.write_text(json.dumps({"interior": io}))
    code, _, err = cli("camera", "convert", src, tmp_path / "x.xml", "--image-size", "4000x3000")
    assert code == 0, err
    back = pg.read_metashape_xml(tmp_path / "x.xml")
    assert (back.width, back.height) == (4000, 3000)
    for name in ("f", "cx", "cy", "b1", "k1", "k2", "k3", "p1", "p2"):
        assert getattr(back, name) == pytest.approx(getattr(CAL, name), rel=1e-12, abs=1e-12)
    code, _, err = cli("camera", "convert", src, tmp_path / "y.xml", "--image-size", "4000,3000")
    assert code == 0, err
    assert (tmp_path / "y.xml").read_bytes() == (tmp_path / "x.xml").read_bytes()
    for bad in ("4000x0", "4000.5x3000", "4000"):
        code, _, err = cli("camera", "convert", src, tmp_path / "z.xml", "--image-size", bad)
        assert code == 2 and "--image-size" in err and "Traceback" not in err, (bad, err)
    assert not (tmp_path / "z.xml").exists()


def test_convert_refusals(cli, tmp_path):
    pg.write_calibration(CAL, tmp_path / "a.xml")
    pg.write_calibration(CAL, tmp_path / "a.yaml")
    before = sorted(p.name for p in tmp_path.iterdir())
    code, _, err = cli("camera", "convert", tmp_path / "a.xml", tmp_path / "b.dat")
    assert code == 2 and "TARGET" in err and ".yaml" in err
    a_yaml = tmp_path / "a.yaml"
    text = a_yaml.read_text()
    a_yaml.write_text(text.replace("image_width: 4000\n", "").replace("image_height: 3000\n", ""))
    code, _, err = cli("camera", "convert", a_yaml, tmp_path / "b.xml")  # read since 11c
    assert code == 2 and "image_width" in err and "--image-size" in err
    code, _, err = cli(
        "camera", "convert", tmp_path / "a.xml", tmp_path / "b.json", "--image-size", "4,3"
    )
    assert code == 2 and "--image-size" in err
    mm = tmp_path / "mm.json"
    mm.write_text('{"f": 100, "unit": "mm"}')
    code, _, err = cli("camera", "convert", mm, tmp_path / "b.xml")
    assert code == 2 and "px" in err
    b2 = pg.MetashapeCalibration(400, 300, 500.0, b2=0.1)
    pg.write_calibration(b2, tmp_path / "b2.xml")
    code, _, err = cli("camera", "convert", tmp_path / "b2.xml", tmp_path / "b.yaml")
    assert code == 2 and "B2" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*before, "mm.json", "b2.xml"])


def test_covariance_with_p3_is_read_without_it(tmp_path):
    p = tmp_path / "m.xml"
    p.write_text(
        '<?xml version="1.0"?><calibration><projection>frame</projection><width>10</width>'
        "<height>8</height><f>12</f><covariance><params>f p3</params>"
        "<coeffs>4 0.5 0.5 1</coeffs></covariance></calibration>"
    )
    names, C = read_metashape_covariance(p)
    assert names == ("f",) and C.tolist() == [[4.0]]
    p.write_text(p.read_text().replace("4 0.5 0.5 1", "4 0.5 0.5"))
    with pytest.raises(pg.FileFormatError, match="expected 4"):
        read_metashape_covariance(p)


def test_convert_reads_a_pipe_once(cli, tmp_path):
    """SOURCE from a pipe (no suffix: the format by content; the XML and its covariance
    from one read)."""
    import os

    pg.write_calibration(CAL, tmp_path / "a.xml", covariance=(NAMES, COV))
    r, w = os.pipe()
    os.write(w, (tmp_path / "a.xml").read_bytes())
    os.close(w)
    try:
        code, _, err = cli("camera", "convert", f"/dev/fd/{r}", tmp_path / "b.json")
    finally:
        os.close(r)
    assert code == 0, err
    d = json.loads((tmp_path / "b.json").read_text())
    assert pg.read_calibration(tmp_path / "b.json") == CAL
    assert set(d["covariance"]["names"]) == set(NAMES)


def test_convert_keeps_the_std_of_a_self_calibrating_resection(cli, tmp_path):
    """orient resection --calibrate f,x0,y0 --output-params -> camera convert: the std and
    covariance of f, x0, y0 become those of f, cx, cy (y0's sign turned: cy = -y0)."""
    pg.write_calibration(CAL, tmp_path / "cal.xml")
    io = CAL.interior_orientation()
    eo = pg.ExteriorOrientation.from_degrees(10, 20, 120, 1, 2, 30)
    rng = np.random.default_rng(0)
    G = np.column_stack(
        [rng.uniform(-60, 80, 25), rng.uniform(-50, 90, 25), rng.uniform(0, 30, 25)]
    )
    px = pg.project(G, io, eo, system="pixel") + rng.normal(0, 0.5, (25, 2))
    lines = ["id,X,Y,Z,col,row"] + [
        f"p{i}," + ",".join(f"{v:.17g}" for v in (*g, *p)) for i, (g, p) in enumerate(zip(G, px))
    ]
    (tmp_path / "ctl.csv").write_text("\n".join(lines) + "\n")
    code, _, err = cli(
        "orient", "resection", tmp_path / "ctl.csv", "--calibration", tmp_path / "cal.xml",
        "--pixel", "--calibrate", "f,x0,y0", "--output-params", tmp_path / "res.json",
    )
    assert code == 0, err
    res = json.loads((tmp_path / "res.json").read_text())
    code, _, err = cli("camera", "convert", tmp_path / "res.json", tmp_path / "cam.json")
    assert code == 0, err
    cam = json.loads((tmp_path / "cam.json").read_text())
    p = res["parameters"]
    assert cam["std"] == {"f": p["f"]["std"], "cx": p["x0"]["std"], "cy": p["y0"]["std"]}
    assert cam["covariance"]["names"] == ["f", "cx", "cy"]
    k = list(p).index("f")
    R = np.array(res["covariance"])[k : k + 3, k : k + 3]
    C = np.array(cam["covariance"]["matrix"])
    np.testing.assert_array_equal(C * np.outer([1, 1, -1], [1, 1, -1]), R)
    assert R[0, 2] != 0
    back = pg.read_calibration(tmp_path / "cam.json")
    assert back.f == pytest.approx(p["f"]["value"], rel=1e-12)
    assert back.cy == pytest.approx(-p["y0"]["value"], rel=1e-9)
