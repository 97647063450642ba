"""`photogeom camera dlt convert --json` output as `--camera` of other commands.

From a camera (``--f ... --eo ...``) the command writes L1..L11 with their unit; given as
``--camera`` that file was refused ("no camera found (expected 'interior'/'exterior'
entries ...)"). It is now decomposed into the camera it holds, as ``camera dlt convert
--params`` does.
"""

from __future__ import annotations

import json

import numpy as np
import pytest


def _projected(text: str) -> np.ndarray:
    rows = [line.split(",") for line in text.splitlines() if line and line[0].isdigit()]
    return np.array([[float(v) for v in r[1:]] for r in rows])


def test_dlt_json_is_a_camera(cli, tmp_path):
    ground = tmp_path / "g.csv"
    ground.write_text("id,X,Y,Z\n1,10,20,0\n2,50,-30,5\n3,-40,10,-3\n")
    cam = ("--f", "1000", "--x0", "500", "--y0", "300", "--unit", "px")
    eo = ("--eo", "10,20,500,1,2,3")
    code, text, err = cli("camera", "dlt", "convert", *cam, *eo, "--json")
    assert code == 0, err
    assert json.loads(text)["model"] == "dlt"
    dlt = tmp_path / "dlt.json"
    dlt.write_text(text)
    code, direct, err = cli("camera", "project", ground, *cam, *eo)
    assert code == 0, err
    code, via, err = cli("camera", "project", ground, "--camera", dlt)
    assert code == 0, err
    assert "px" in via.splitlines()[0]
    np.testing.assert_allclose(_projected(via), _projected(direct), atol=1e-9)
    # the decomposed cameras also serve orient intersection: the points come back
    code, text, err = cli("camera", "dlt", "convert", *cam, "--eo", "60,20,500,1,2,3", "--json")
    assert code == 0, err
    dlt2 = tmp_path / "dlt2.json"
    dlt2.write_text(text)
    code, via2, err = cli("camera", "project", ground, "--camera", dlt2)
    assert code == 0, err
    img1, img2 = tmp_path / "i1.csv", tmp_path / "i2.csv"
    img1.write_text("\n".join(line for line in via.splitlines() if not line.startswith("#")))
    img2.write_text("\n".join(line for line in via2.splitlines() if not line.startswith("#")))
    out = tmp_path / "xyz.csv"
    code, _, err = cli(
        "orient", "intersection", img1, img2, "--camera", dlt, "--camera", dlt2, "-o", out
    )
    assert code == 0, err
    from photogeom.io import read_points

    got = read_points(out, ["X", "Y", "Z"]).coords
    np.testing.assert_allclose(got, [[10, 20, 0], [50, -30, 5], [-40, 10, -3]], atol=1e-6)


def test_singular_dlt_names_the_problem(cli, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(
        json.dumps({"model": "dlt", "unit": "mm", **{f"L{k}": 0.0 for k in range(1, 12)}})
    )
    ground = tmp_path / "g.csv"
    ground.write_text("id,X,Y,Z\n1,10,20,0\n")
    code, _, err = cli("camera", "project", ground, "--camera", bad)
    assert code == 2
    assert "a DLT (L1..L11) that gives no camera" in err and "Traceback" not in err


def _pixel_control(cli, tmp_path):
    rng = np.random.default_rng(3)
    g = np.column_stack(
        [rng.uniform(-100, 100, 12), rng.uniform(-100, 100, 12), rng.uniform(-20, 20, 12)]
    )
    ground = tmp_path / "gr.csv"
    ground.write_text("id,X,Y,Z\n" + "".join(f"{i},{a!r},{b!r},{c!r}\n" for i, (a, b, c) in
                                              enumerate(g.tolist())))  # fmt: skip
    pix = tmp_path / "pix.csv"
    code, _, err = cli("camera", "project", ground, "--f", "1000", "--unit", "px",
                       "--principal-point", "500,300", "--eo", "10,20,800,1,2,3", "--pixel",
                       "-o", pix)  # fmt: skip
    assert code == 0, err
    return ground, pix


def test_dlt_estimate_takes_the_pixels_of_camera_project(cli, tmp_path):
    ground, pix = _pixel_control(cli, tmp_path)
    # before: no --pixel; with --image-cols col,row "left-handed ... convert them" (by hand)
    code, _, err = cli("camera", "dlt", "estimate", ground, pix, "--unit", "px",
                       "--image-cols", "col,row")  # fmt: skip
    assert code == 2 and "give --pixel" in err
    params = tmp_path / "dlt.json"
    code, out, err = cli("camera", "dlt", "estimate", ground, pix, "--pixel", "--output-params",
                         params)  # fmt: skip
    assert code == 0, err
    assert "principal point col 500.000000, row 300.000000 px" in out
    data = json.loads(params.read_text())
    assert data["pixel"]["principal_point_px"] == pytest.approx([500.0, 300.0], abs=1e-6)
    io = data["orientation"]["interior"]
    assert io["f"] == pytest.approx(1000.0, abs=1e-6) and io["unit"] == "px"
    # the camera written projects back to the pixels it was estimated from
    code, back, err = cli("camera", "project", ground, "--camera", params, "--pixel")
    assert code == 0, err
    from photogeom.io import read_points

    want = read_points(pix, ["col", "row"]).coords
    np.testing.assert_allclose(_projected(back), want, atol=1e-6)


def test_dlt_estimate_pixel_refuses_mm(cli, tmp_path):
    ground, pix = _pixel_control(cli, tmp_path)
    code, _, err = cli("camera", "dlt", "estimate", ground, pix, "--pixel", "--unit", "mm")
    assert code == 2 and "--unit mm with --pixel" in err
