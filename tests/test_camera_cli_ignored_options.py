"""`camera project` and `camera dlt convert`: camera options the chosen camera source ignores
are refused, naming them.

They used to be dropped silently: --x0/--y0 next to --principal-point; --unit, --pixel-size,
--x0, --y0, --principal-point next to --calibration or --camera; the camera options next to
--dlt/--params.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg

EO = "1114,862,1600,2,3,10"
IO = pg.InteriorOrientation(152.14, 0.008, -0.12)


@pytest.fixture
def files(tmp_path):
    pts = tmp_path / "g.csv"
    pts.write_text("id,X,Y,Z\nA,1300,650,169\nB,1250,700,150\n")
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"interior": IO.to_dict()}))
    cal = tmp_path / "cal.xml"
    pg.write_metashape_xml(pg.MetashapeCalibration(width=6000, height=4000, f=5000.0), cal)
    return {"pts": pts, "cam": cam, "cal": cal}


def _points(out: str) -> np.ndarray:
    rows = [ln.split(",") for ln in out.splitlines() if ln and not ln.startswith("#")][1:]
    return np.array([[float(v) for v in r[1:]] for r in rows])


@pytest.mark.parametrize(
    "source, extra, named",
    [
        (["--f", "10000", "--unit", "px", "--principal-point", "3840,6912"], ["--x0", "5"],
         "--x0"),
        (["--f", "1e4", "--unit", "px", "--principal-point", "3840,6912"],
         ["--x0", "0", "--y0", "1"], "--x0 and --y0"),
        (["--camera", "CAM"], ["--x0", "0.5"], "--x0"),
        (["--camera", "CAM"], ["--unit", "px"], "--unit"),
        (["--camera", "CAM"], ["--unit", "mm"], "--unit"),
        (["--calibration", "CAL"], ["--unit", "mm", "--pixel-size", "0.004"],
         "--unit, --pixel-size"),
        (["--calibration", "CAL"], ["--principal-point", "3000,2000"], "--principal-point"),
        (["--calibration", "CAL"], ["--y0", "1"], "--y0"),
    ],
)  # fmt: skip
def test_project_refuses_options_the_camera_ignores(cli, files, source, extra, named):
    source = [
        str(files["cam"]) if a == "CAM" else str(files["cal"]) if a == "CAL" else a for a in source
    ]
    code, out, err = cli("camera", "project", files["pts"], *source, "--eo", EO)
    assert code == 0, err  # the camera alone works
    code, out, err = cli("camera", "project", files["pts"], *source, *extra, "--eo", EO)
    assert code == 2 and out == ""
    assert err.startswith("error: ") and named in err


def test_project_options_that_are_used_still_work(cli, files):
    """The documented forms give the library's projection."""
    eo = pg.ExteriorOrientation.from_degrees(*map(float, EO.split(",")))
    xyz = np.array([[1300, 650, 169], [1250, 700, 150]], dtype=float)
    code, out, err = cli("camera", "project", files["pts"], "--f", "152.14", "--x0", "0.008",
                         "--y0", "-0.12", "--eo", EO)  # fmt: skip
    assert code == 0, err
    np.testing.assert_allclose(_points(out), pg.project(xyz, IO, eo), atol=1e-9)
    code, out2, err = cli("camera", "project", files["pts"], "--camera", files["cam"], "--eo", EO)
    assert code == 0, err
    assert out2 == out
    digital = pg.InteriorOrientation.digital(5000.0, 3000.0, 2000.0, unit="px", pixel_size=0.004)
    code, out, err = cli("camera", "project", files["pts"], "--f", "5000", "--unit", "px",
                         "--principal-point", "3000,2000", "--pixel-size", "0.004", "--eo", EO,
                         "--pixel")  # fmt: skip
    assert code == 0, err
    np.testing.assert_allclose(
        _points(out), pg.project(xyz, digital, eo, system="pixel"), atol=1e-6
    )


@pytest.mark.parametrize(
    "args, named",
    [
        (["--dlt", ",".join(["1"] * 11), "--f", "152"], "--f"),
        (["--dlt", ",".join(["1"] * 11), "--eo", EO], "--eo"),
        (["--dlt", ",".join(["1"] * 11), "--x0", "0.1", "--y0", "0.2"], "--x0, --y0"),
        (["--camera", "CAM", "--eo", EO, "--x0", "0.1"], "--x0"),
        (["--camera", "CAM", "--eo", EO, "--unit", "px"], "--unit"),
    ],
)
def test_dlt_convert_refuses_options_it_would_ignore(cli, files, args, named):
    args = [str(files["cam"]) if a == "CAM" else a for a in args]
    code, out, err = cli("camera", "dlt", "convert", *args)
    assert code == 2 and out == "" and named in err


def test_dlt_convert_params_unit(cli, files, tmp_path):
    eo = pg.ExteriorOrientation.from_degrees(*map(float, EO.split(",")))
    L = pg.camera.dlt_from_orientation(IO, eo)
    params = tmp_path / "dlt.json"
    params.write_text(json.dumps(pg.camera.DLT(L, "mm").to_dict()))
    code, out, err = cli("camera", "dlt", "convert", "--params", params)
    assert code == 0, err
    code, out2, err = cli("camera", "dlt", "convert", "--params", params, "--unit", "mm")
    assert code == 0, err
    assert out2 == out
    code, _, err = cli("camera", "dlt", "convert", "--params", params, "--unit", "px")
    assert code == 2 and "--unit px" in err and "records its DLT in mm" in err
    code, out, err = cli("camera", "dlt", "convert", "--camera", files["cam"], "--eo", EO, "--json")
    assert code == 0, err
    np.testing.assert_allclose([json.loads(out)[f"L{i}"] for i in range(1, 12)], L, rtol=1e-12)
