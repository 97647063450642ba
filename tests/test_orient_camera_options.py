"""`orient resection` and `orient relative`: camera options the chosen camera source ignores
are refused, naming them, before any file is read (as `camera project` does).

They used to be dropped silently: --x0/--y0 next to --principal-point; --unit, --pixel-size,
--x0, --y0, --principal-point next to --calibration or --camera.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg

IO = pg.InteriorOrientation(152.14, 0.008, -0.12)
EO = pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10)
CAMERA = ["--f", "152.14", "--x0", "0.008", "--y0", "-0.12"]
# a digital camera: f, principal point in pixels, pixel size
DIGITAL = pg.InteriorOrientation.digital(10000.0, 3000.0, 2000.0, unit="px", pixel_size=0.004)
PX = ["--f", "10000", "--unit", "px", "--principal-point", "3000,2000", "--pixel-size", "0.004"]
E1 = pg.ExteriorOrientation(0.0, 0.0, 100.0, 0.02, -0.03, 0.01)
E2 = pg.ExteriorOrientation(60.0, 3.0, 101.0, -0.01, 0.02, 0.05)


def _rows(ids, *arrays) -> str:
    rows = np.column_stack(arrays)
    return "".join(f"{i}," + ",".join(repr(float(v)) for v in r) + "\n" for i, r in zip(ids, rows))


@pytest.fixture
def files(tmp_path):
    rng = np.random.default_rng(4)
    g = np.column_stack(
        [rng.uniform(1050, 1550, 10), rng.uniform(750, 1100, 10), rng.uniform(100, 300, 10)]
    )
    ids = [f"P{i}" for i in range(10)]
    xy = pg.project(g, IO, EO) + rng.normal(0, 0.003, (10, 2))
    ctl = tmp_path / "control.csv"
    ctl.write_text("id,X,Y,Z,x,y\n" + _rows(ids, g, xy))
    cr = DIGITAL.image_to_pixel(pg.project(g, DIGITAL, EO)) + rng.normal(0, 0.3, (10, 2))
    ctl_px = tmp_path / "control_px.csv"
    ctl_px.write_text("id,X,Y,Z,col,row\n" + _rows(ids, g, cr))
    pts = np.column_stack(
        [rng.uniform(-30, 90, 30), rng.uniform(-40, 40, 30), rng.uniform(-10, 10, 30)]
    )
    mm = pg.InteriorOrientation(100.0, 0.01, -0.02)
    m = np.column_stack([pg.project(pts, mm, E1), pg.project(pts, mm, E2)])
    m += rng.normal(0, 0.004, m.shape)
    matches = tmp_path / "matches.csv"
    matches.write_text("id,x1,y1,x2,y2\n" + _rows(range(30), m))
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"interior": IO.to_dict()}))
    cal = tmp_path / "cal.xml"
    pg.write_metashape_xml(
        pg.MetashapeCalibration(width=6000, height=4000, f=10000.0, cx=0.0, cy=0.0), cal
    )
    return {"ctl": ctl, "ctl_px": ctl_px, "matches": matches, "cam": cam, "cal": cal, "g": g,
            "xy": xy, "cr": cr}  # fmt: skip


REFUSED = [
    (["--f", "1e4", "--unit", "px", "--principal-point", "3000,2000"], ["--x0", "5"], "--x0"),
    (["--f", "1e4", "--unit", "px", "--principal-point", "3000,2000"],
     ["--x0", "0", "--y0", "1"], "--x0 and --y0"),
    (["--camera", "CAM"], ["--x0", "0.5"], "--x0"),
    (["--camera", "CAM"], ["--unit", "mm"], "--unit"),
    (["--camera", "CAM"], ["--principal-point", "3000,2000"], "--principal-point"),
    (["--calibration", "CAL"], ["--unit", "px", "--pixel-size", "0.004"], "--unit, --pixel-size"),
    (["--calibration", "CAL"], ["--y0", "1"], "--y0"),
]  # fmt: skip


def _same(a: str, b: str) -> bool:
    """Two --json outputs agree (but for the run time)."""
    da, db = json.loads(a), json.loads(b)
    da.pop("elapsed_s", None)
    db.pop("elapsed_s", None)
    return da == db


def _args(files, source):
    return [str(files["cam"]) if a == "CAM" else str(files["cal"]) if a == "CAL" else a
            for a in source]  # fmt: skip


@pytest.mark.parametrize("source, extra, named", REFUSED)
def test_resection_refuses_options_the_camera_ignores(cli, files, source, extra, named):
    source = _args(files, source)
    code, out, err = cli("orient", "resection", files["ctl"], *source)
    assert code == 0, err  # the camera alone works
    code, out, err = cli("orient", "resection", files["ctl"], *source, *extra)
    assert code == 2 and out == ""
    assert err.startswith("error: ") and named in err
    # refused before any file is read: a missing points file is not reached
    code, out, err = cli("orient", "resection", files["ctl"].with_name("none.csv"), *source,
                         *extra)  # fmt: skip
    assert code == 2 and named in err and "none.csv" not in err


@pytest.mark.parametrize("source, extra, named", REFUSED)
def test_relative_refuses_options_the_camera_ignores(cli, files, source, extra, named):
    source = _args(files, source)
    code, out, err = cli("orient", "relative", files["matches"], *source, *extra)
    assert code == 2 and out == ""
    assert err.startswith("error: ") and named in err
    code, out, err = cli("orient", "relative", files["matches"].with_name("none.csv"), *source,
                         *extra)  # fmt: skip
    assert code == 2 and named in err and "none.csv" not in err


def test_resection_documented_cameras_give_the_library_numbers(cli, files, tmp_path):
    ctl = files["ctl"]
    code, out, err = cli("orient", "resection", ctl, *CAMERA, "--json")
    assert code == 0, err
    fit = pg.space_resection(files["g"], files["xy"], IO)
    params = json.loads(out)["parameters"]
    for k, v in fit.params.items():
        assert params[k]["value"] == pytest.approx(v, abs=1e-9)
    # the same camera from a JSON file: the same output
    code, out2, err = cli("orient", "resection", ctl, "--camera", files["cam"], "--json")
    assert code == 0, err
    assert _same(out2, out)
    # --unit mm and x0 = y0 = 0 are the defaults
    code, out, err = cli("orient", "resection", ctl, "--f", "152.14", "--json")
    assert code == 0, err
    code, out2, err = cli("orient", "resection", ctl, "--f", "152.14", "--x0", "0", "--y0", "0",
                          "--unit", "mm", "--json")  # fmt: skip
    assert code == 0, err
    assert _same(out2, out)
    # a digital camera: --principal-point and --pixel-size with --pixel
    code, out, err = cli("orient", "resection", files["ctl_px"], *PX, "--pixel", "--json")
    assert code == 0, err
    fit = pg.space_resection(files["g"], DIGITAL.pixel_to_image(files["cr"]), DIGITAL)
    params = json.loads(out)["parameters"]
    for k, v in fit.params.items():
        assert params[k]["value"] == pytest.approx(v, abs=1e-9)
    # the documented --calibration camera.xml --pixel --sigma 0.5
    code, out, err = cli("orient", "resection", files["ctl_px"], "--calibration", files["cal"],
                         "--pixel", "--sigma", "0.5", "--json")  # fmt: skip
    assert code == 0, err
    io = pg.read_metashape_xml(files["cal"]).interior_orientation()
    fit = pg.space_resection(files["g"], io.pixel_to_image(files["cr"]), io, sigma=0.5)
    params = json.loads(out)["parameters"]
    for k, v in fit.params.items():
        assert params[k]["value"] == pytest.approx(v, abs=1e-9)


def test_relative_documented_cameras_give_the_library_numbers(cli, files):
    data = np.loadtxt(files["matches"], delimiter=",", skiprows=1, usecols=(1, 2, 3, 4))
    mm = pg.InteriorOrientation(100.0, 0.01, -0.02)
    code, out, err = cli("orient", "relative", files["matches"], "--f", "100", "--x0", "0.01",
                         "--y0", "-0.02", "--sigma", "0.004", "--json")  # fmt: skip
    assert code == 0, err
    fit = pg.relative_orientation(data[:, :2], data[:, 2:], mm, sigma=0.004,
                                  ids=[str(i) for i in range(30)])  # fmt: skip
    params = json.loads(out)["parameters"]
    for k, v in fit.params.items():
        assert params[k]["value"] == pytest.approx(v, abs=1e-12)
    cam = files["cam"].with_name("mm.json")
    cam.write_text(json.dumps({"interior": mm.to_dict()}))
    code, out2, err = cli("orient", "relative", files["matches"], "--camera", cam, "--sigma",
                          "0.004", "--json")  # fmt: skip
    assert code == 0, err
    assert _same(out2, out)
