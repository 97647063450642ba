"""An adjusted calibration handed to other tools (Metashape XML, camera JSON,
OpenCV YAML): ``pg.write_calibration`` and ``bundle adjust --output-calibration``.

Before, no function or command wrote a calibration as photogeom camera JSON or OpenCV
YAML, nor any calibration with its standard deviations, and ``bundle adjust`` had no
option to write the adjusted calibration (``No such option: --output-calibration``).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import fields

import numpy as np
import pytest

import photogeom as pg
from photogeom.camera.calibration_files import calibration_json

CAL = pg.MetashapeCalibration(
    4000, 3000, 2800.123, cx=12.3, cy=-7.9, k1=-0.11, k2=0.05, k3=-0.01, p1=3e-4, p2=-2e-4,
    b1=1.7,
)
NAMES = ("f", "cx", "cy", "k1", "p1", "b1")
COV = np.diag([4.0, 1.0, 2.25, 1e-6, 1e-8, 0.09])
COV[0, 5] = COV[5, 0] = -0.3
SMALL = ["--strips", "2", "--images-per-strip", "4", "--tie-points-per-image", "60"]


def _points(n=200, seed=3):
    rng = np.random.default_rng(seed)
    z = rng.uniform(8, 12, n)
    return np.column_stack([rng.uniform(-0.6, 0.6, n) * z, rng.uniform(-0.45, 0.45, n) * z, z])


def _same(a: pg.MetashapeCalibration, b: pg.MetashapeCalibration, atol=1e-12):
    for fl in fields(a):
        va, vb = getattr(a, fl.name), getattr(b, fl.name)
        assert abs(va - vb) <= atol * max(1.0, abs(va)), (fl.name, va, vb)


@pytest.mark.parametrize("suffix", ["xml", "json"])
def test_round_trip_with_photogeoms_readers(tmp_path, suffix):
    path = tmp_path / f"cal.{suffix}"
    fmt = pg.write_calibration(CAL, path, covariance=(NAMES, COV))
    assert fmt == {"xml": "metashape", "json": "json"}[suffix]
    assert pg.read_calibration(path) == CAL  # exact: 17 significant digits
    if suffix == "xml":
        assert pg.read_metashape_xml(path, strict=True) == CAL  # <covariance> is known
    X = _points()
    np.testing.assert_array_equal(
        pg.read_calibration(path).project_camera(X), CAL.project_camera(X)
    )


def test_camera_json_is_what_camera_reads(tmp_path):
    from photogeom.cli.camera import camera_from_json

    path = tmp_path / "cal.json"
    pg.write_calibration(CAL, path, covariance=(NAMES, COV))
    io, eo = camera_from_json(path)
    assert eo is None and io.unit == "px"
    _same(pg.MetashapeCalibration.from_interior_orientation(io), CAL)
    data = json.loads(path.read_text())
    assert data["std"] == pytest.approx(
        {"f": 2.0, "cx": 1.0, "cy": 1.5, "k1": 1e-3, "p1": 1e-4, "b1": 0.3}, rel=1e-15
    )
    assert data["covariance"]["names"] == list(NAMES)
    np.testing.assert_array_equal(data["covariance"]["matrix"], COV)


def test_json_std_leaves_held_parameters_out():
    std = {n: np.nan for n in ("f", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")}
    std["f"] = 0.5
    d = calibration_json(CAL, std=std)
    assert d["std"] == {"f": 0.5} and "covariance" not in d
    json.dumps(d, allow_nan=False)  # no NaN in the file


def test_metashape_covariance_in_metashapes_order(tmp_path):
    path = tmp_path / "cal.xml"
    pg.write_calibration(CAL, path, covariance=(NAMES, COV))
    cov = ET.parse(path).getroot().find("covariance")
    names = cov.find("params").text.split()
    assert names == ["f", "cx", "cy", "b1", "k1", "p1"]
    C = np.array(cov.find("coeffs").text.split(), dtype=float).reshape(6, 6)
    idx = [NAMES.index(n) for n in names]
    np.testing.assert_array_equal(C, COV[np.ix_(idx, idx)])


def test_opencv_yaml_projects_as_photogeom(tmp_path):
    cv2 = pytest.importorskip("cv2")
    path = tmp_path / "cal.yaml"
    assert pg.write_calibration(CAL, path, covariance=(NAMES, COV)) == "opencv"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    K = fs.getNode("camera_matrix").mat()
    dist = fs.getNode("distortion_coefficients").mat()
    std = fs.getNode("std_deviations_intrinsics").mat().ravel()
    size = (int(fs.getNode("image_width").real()), int(fs.getNode("image_height").real()))
    fs.release()
    assert size == (4000, 3000)
    X = _points()
    uv, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, dist)
    np.testing.assert_allclose(uv[:, 0], CAL.project_camera(X), rtol=0, atol=1e-9)
    _same(pg.MetashapeCalibration.from_opencv(K, dist, *size), CAL)
    # fx = f + b1: var = 4 + 0.09 - 2 * 0.3; OpenCV's p1, p2 are Metashape's p2, p1
    np.testing.assert_allclose(
        std, [np.sqrt(3.49), 2.0, 1.0, 1.5, 1e-3, 0.0, 0.0, 1e-4, 0.0], rtol=1e-15
    )


def test_opencv_refuses_k4_and_b2_and_other_suffixes(tmp_path):
    with pytest.raises(pg.InputError, match="B2"):
        pg.write_calibration(pg.MetashapeCalibration(400, 300, 500.0, b2=0.1), tmp_path / "c.yml")
    with pytest.raises(pg.InputError, match=r"\.xml .*\.json .*\.yaml"):
        pg.write_calibration(CAL, tmp_path / "c.dat")
    assert list(tmp_path.iterdir()) == []


# --- bundle adjust --output-calibration ---------------------------------------------------------


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    from photogeom.cli.main import main

    d = tmp_path_factory.mktemp("sim") / "block"
    try:
        main(["bundle", "simulate", str(d), "--seed", "3", *SMALL])
    except SystemExit as exc:  # pragma: no cover - a failure shows in the asserts below
        assert exc.code in (0, None)
    return d


FREE = "f,cx,cy,k1,k2,k3,p1,p2,b1"


def test_bundle_adjust_writes_the_adjusted_calibration(block, cli, tmp_path):
    code, out, err = cli(
        "bundle", "adjust", block, "--free", FREE, "--json",
        "--output-calibration", tmp_path / "cal.xml",
    )
    assert code == 0, err
    res = json.loads(out)
    code, _, err = cli(
        "bundle", "adjust", block, "--free", FREE, "--output-calibration", tmp_path / "cal.json"
    )
    assert code == 0, err
    (group,) = res["calibration"]
    adjusted = res["calibration"][group]
    xml_cal = pg.read_metashape_xml(tmp_path / "cal.xml", strict=True)
    for name, value in adjusted.items():
        assert getattr(xml_cal, name) == value
    data = json.loads((tmp_path / "cal.json").read_text())
    assert pg.read_calibration(tmp_path / "cal.json") == xml_cal
    std = res["calibration_std"][group]
    assert data["std"] == {n: std[n] for n in FREE.split(",")}
    # the camera JSON and the XML give the same projection in 'camera project'
    pts = tmp_path / "pts.csv"
    pts.write_text("id,X,Y,Z\na,10,20,0\nb,-30,5,3\n")
    outs = []
    for opt in (["--camera", tmp_path / "cal.json"], ["--calibration", tmp_path / "cal.xml"]):
        code, out, err = cli("camera", "project", pts, *opt, "--eo", "0,0,100,1,2,3", "--pixel")
        assert code == 0, err
        outs.append(out)
    assert outs[0] == outs[1]


def test_bundle_adjust_refusals_come_before_the_adjustment(block, cli, tmp_path):
    code, _, err = cli("bundle", "adjust", block, "--output-calibration", tmp_path / "c.dat")
    assert code == 2 and "--output-calibration" in err and ".yaml" in err
    code, _, err = cli(
        "bundle", "adjust", block, "--free", "f,b2", "--output-calibration", tmp_path / "c.yaml"
    )
    assert code == 2 and "B2" in err and "--free" in err
    code, _, err = cli(
        "bundle", "adjust", block,
        "--output-calibration", tmp_path / "c.json", "--result", tmp_path / "c.json",
    )
    assert code == 2 and "--output-calibration" in err and "--result" in err
    assert list(tmp_path.iterdir()) == []


def test_several_groups_get_one_file_each(tmp_path):
    from photogeom.cli.bundle import calibration_targets

    p = tmp_path / "cal.xml"
    assert calibration_targets(p, ["A"]) == [("A", p)]
    assert calibration_targets(p, ["A", "b/c"]) == [
        ("A", tmp_path / "cal-A.xml"),
        ("b/c", tmp_path / "cal-b_c.xml"),
    ]
    with pytest.raises(pg.InputError, match="both be written"):
        calibration_targets(p, ["a/b", "a_b"])


def test_opencv_without_estimated_parameters_has_no_std(tmp_path):
    cv2 = pytest.importorskip("cv2")
    pg.write_calibration(CAL, tmp_path / "c.yaml", covariance=((), np.zeros((0, 0))))
    fs = cv2.FileStorage(str(tmp_path / "c.yaml"), cv2.FILE_STORAGE_READ)
    assert fs.getNode("std_deviations_intrinsics").empty()  # before: nine zeros
    fs.release()


def test_image_variant_group_is_noted(block, cli, tmp_path):
    """A file holds one calibration: for a group estimated per image, the group's value;
    the command says so (the images' offsets are in --json / --result)."""
    import shutil

    b = tmp_path / "iv"
    shutil.copytree(block, b)
    cams = (b / "cameras.csv").read_text().splitlines()
    head = cams[1].split(",")
    k = head.index("image_variant")
    row = cams[2].split(",")
    row[k] = "f cx cy"
    cams[2] = ",".join(row)
    (b / "cameras.csv").write_text("\n".join(cams) + "\n")
    code, _, err = cli("bundle", "adjust", b, "--output-calibration", tmp_path / "c.json")
    assert code == 0, err
    assert "per image" in err and "offsets" in err
    assert "f" not in json.loads((tmp_path / "c.json").read_text())["std"]
