"""``orient intersection --camera c1.json ... -o c1.json`` replaced the camera file with the
intersected points (exit 0): only the IMAGES were checked as inputs. The
``--camera`` files are now inputs too, refused as destinations before the computation; so
are the ``--camera``, ``--camera2`` and ``--calibration`` files of ``orient relative`` and
``orient resection``, which were replaced the same way."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from photogeom import datasets


@pytest.fixture
def block(cli, tmp_path: Path) -> dict[str, Path]:
    pts = tmp_path / "pts.csv"
    shutil.copyfile(datasets.path("lecture_two_images"), pts)
    c1, c2 = tmp_path / "c1.json", tmp_path / "c2.json"
    code, _, err = cli("orient", "relative", pts, "--f", "100", "--unit", "px", "--method",
                       "independent", "--output-cameras", c1, c2)
    assert code == 0, err
    rows = [ln.split(",") for ln in pts.read_text().splitlines() if not ln.startswith("#")]
    images = []
    for k, (x, y) in enumerate(((1, 2), (3, 4)), start=1):
        f = tmp_path / f"img{k}.csv"
        f.write_text("\n".join(["id,x,y"] + [f"{r[0]},{r[x]},{r[y]}" for r in rows[1:]]) + "\n")
        images.append(f)
    return {"i1": images[0], "i2": images[1], "c1": c1, "c2": c2}


@pytest.mark.parametrize("option,cam", [("-o", "c1"), ("--report", "c2")])
def test_an_output_onto_a_camera_file_is_refused(cli, block, option, cam):
    before = block[cam].read_bytes()
    code, _, err = cli("orient", "intersection", block["i1"], block["i2"], "--camera",
                       block["c1"], "--camera", block["c2"], option, block[cam])
    assert code == 2
    assert f"is the input file --camera {block[cam]}" in err
    assert block[cam].read_bytes() == before


def test_other_outputs_are_written(cli, block, tmp_path: Path):
    out = tmp_path / "xyz.csv"
    code, _, err = cli("orient", "intersection", block["i1"], block["i2"], "--camera",
                       block["c1"], "--camera", block["c2"], "-o", out)
    assert code == 0, err
    assert out.is_file()


@pytest.mark.parametrize(
    "camera_option,output_option",
    [("--camera", "--report"), ("--camera2", "-o"), ("--calibration", "-o")],
)
def test_orient_relative_keeps_its_camera_files(cli, block, tmp_path, camera_option,
                                                output_option):
    """orient relative --camera c.json --report c.json replaced the camera with the report
    (exit 0); likewise --camera2 and --calibration."""
    if camera_option == "--calibration":
        from photogeom.camera.metashape import MetashapeCalibration, write_metashape_xml

        given = tmp_path / "cal.xml"
        write_metashape_xml(MetashapeCalibration(1000, 800, 100.0), given)
        extra = [camera_option, given]
    elif camera_option == "--camera2":
        given = block["c2"]
        extra = ["--camera", block["c1"], camera_option, given]
    else:
        given = block["c1"]
        extra = [camera_option, given]
    before = given.read_bytes()
    pts = datasets.path("lecture_two_images")
    code, _, err = cli("orient", "relative", pts, "--method", "independent", *extra,
                       output_option, given)
    assert code == 2
    assert f"is the input file {camera_option}:" in err
    assert given.read_bytes() == before


def test_orient_resection_keeps_its_camera_file(cli, block):
    before = block["c1"].read_bytes()
    code, _, err = cli("orient", "resection", block["i1"], "--camera", block["c1"],
                       "--report", block["c1"])
    assert code == 2
    assert "is the input file --camera:" in err
    assert block["c1"].read_bytes() == before
