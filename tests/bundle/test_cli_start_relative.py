"""bundle adjust --start relative: a CSV block without start values (no GNSS/IMU, no
exterior orientations, no tie-point coordinates) takes them from relative orientations,
strips and its control points, and reaches the minimum the adjustment reaches from the true
values."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import photogeom as pg


@pytest.fixture(scope="module")
def sim():
    # without GNSS/IMU, the start 30 m and 20 degrees off (FC300S, 56 m flying height)
    return pg.simulate.uav_block(
        "FC300S",
        seed=1,
        strips=2,
        images_per_strip=5,
        gnss_sigma=None,
        imu_sigma_deg=None,
        initial_position_error=30.0,
        initial_attitude_error_deg=20.0,
    )


@pytest.fixture(scope="module")
def reference(sim):
    """The adjustment from the true exterior orientations and tie points."""
    tie = (sim.block.role == "tie")[:, None]
    return pg.bundle_adjust(
        sim.block.replace(
            exterior=sim.truth.exterior.copy(), xyz=np.where(tie, sim.truth.xyz, sim.block.xyz)
        )
    )


def _without_start(sim, folder, *, columns: bool):
    """The block's CSV folder with the exterior orientations and the tie points' X, Y, Z
    removed: the columns left out (``columns=False``) or their cells emptied."""
    pg.bundle.write_csv_block(sim.block, folder)
    images = (folder / "images.csv").read_text().splitlines()
    rows = [r for r in images if not r.startswith("#")]
    keep = 2 if not columns else len(rows[0].split(","))
    out = []
    for r in rows:
        cells = r.split(",")[:keep]
        if columns and r is not rows[0]:
            cells[2:8] = [""] * 6
        out.append(",".join(cells))
    (folder / "images.csv").write_text("\n".join(out) + "\n")
    points = []
    for r in (folder / "points.csv").read_text().splitlines():
        cells = r.split(",")
        if len(cells) > 4 and cells[1] == "tie":
            cells[2:5] = ["", "", ""]
        points.append(",".join(cells))
    (folder / "points.csv").write_text("\n".join(points) + "\n")
    return folder


def _ids(sim, k):
    return ",".join(map(str, sim.block.image_ids[5 * k : 5 * k + 5].tolist()))


def test_without_start_values_the_error_names_the_route(sim, cli, tmp_path):
    d = _without_start(sim, tmp_path / "b", columns=False)
    code, _, err = cli("bundle", "adjust", d)
    assert code != 0
    assert "column 'X0' not found" in err and "--start relative" in err
    d = _without_start(sim, tmp_path / "c", columns=True)
    code, _, err = cli("bundle", "adjust", d)
    assert code != 0
    assert "column 'X0' is empty" in err and "--start relative" in err
    assert "read_csv_block" not in err  # the library's words are the options'


@pytest.mark.parametrize(("strips", "columns"), [("found", False), ("given", True)])
def test_start_relative_reaches_the_minimum_from_the_truth(
    sim, reference, cli, tmp_path, columns, strips
):
    d = _without_start(sim, tmp_path / "b", columns=columns)
    given = ["--strips", f"{_ids(sim, 0)};{_ids(sim, 1)}"] if strips == "given" else []
    code, out, err = cli("bundle", "adjust", d, "--start", "relative", *given, "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["converged"] and res["input"]["start"] == "relative"
    assert res["sigma0"] == pytest.approx(reference.sigma0, rel=1e-6)
    got = np.array([[i["X0"], i["Y0"], i["Z0"]] for i in res["images"]])
    np.testing.assert_allclose(got, reference.block.exterior[:, :3], rtol=0, atol=1e-4)


def test_the_summary_says_where_the_start_values_came_from(sim, cli, tmp_path):
    d = _without_start(sim, tmp_path / "b", columns=False)
    code, out, err = cli("bundle", "adjust", d, "--start", "relative")
    assert code == 0, err
    assert "start values from relative orientations: 1 strip(s) of 10 images" in out
    assert "oriented to 5 control point(s)" in out


@pytest.mark.parametrize(
    ("strips", "match"),
    [
        ("0,1,2,3,4;5,6,7,8,99", r"--strips: '99' is not an image id of the block"),
        ("0,1,2,3,4;5,6,7,8", r"--strips: 1 image\(s\) in no strip \(9\)"),
        ("0,1,2,3,4;4,5,6,7,8,9", r"--strips: image\(s\) 4 listed twice"),
        ("0,1,2,3,4,5,6,7,8;9", r"--strips: strip '9' has one image"),
    ],
)
def test_bad_strips_are_named(sim, cli, tmp_path, strips, match):
    d = _without_start(sim, tmp_path / "b", columns=False)
    code, _, err = cli("bundle", "adjust", d, "--start", "relative", "--strips", strips)
    assert code != 0
    assert re.search(match, err), err


def test_strips_without_start_relative_is_refused(sim, cli, tmp_path):
    pg.bundle.write_csv_block(sim.block, tmp_path / "b")
    code, _, err = cli("bundle", "adjust", tmp_path / "b", "--strips", "0,1")
    assert code != 0 and "--strips is for --start relative" in err


def test_images_out_of_flight_order(sim, reference, cli, tmp_path):
    # image 9 (end of the second strip, beside image 0 in the serpentine) moved between
    # images 0 and 1: the found strips follow the file and still reach the minimum
    d = _without_start(sim, tmp_path / "b", columns=False)
    rows = (d / "images.csv").read_text().splitlines()
    rows = [rows[0], rows[1], rows[10], *rows[2:10]]
    (d / "images.csv").write_text("\n".join(rows) + "\n")
    code, out, err = cli("bundle", "adjust", d, "--start", "relative", "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["converged"]
    assert res["sigma0"] == pytest.approx(reference.sigma0, rel=1e-6)


def test_csv_reader_without_start_values_keeps_control(sim, tmp_path):
    d = _without_start(sim, tmp_path / "b", columns=True)
    with pytest.raises(pg.FileFormatError, match="start_from_relative_orientation"):
        pg.bundle.read_csv_block(d)
    block = pg.bundle.read_csv_block(d, start_values=False)
    control = block.role != "tie"
    np.testing.assert_allclose(block.xyz[control], sim.block.xyz[control], atol=1e-9)
    assert np.all(block.exterior == 0.0) and np.all(block.xyz[~control] == 0.0)


def test_a_tie_point_without_start_value_is_named(sim, cli, tmp_path):
    # a point measured in images 0 and 4 (no relative orientation of the strip pairs them)
    # whose rays cross behind the cameras: it would keep the placeholder 0 of its empty cells
    d = _without_start(sim, tmp_path / "b", columns=False)
    h = sim.camera.height
    with open(d / "points.csv", "a") as f:
        f.write("999,tie,,,,,,\n")
    with open(d / "observations.csv", "a") as f:
        f.write(f"0,999,10,{h - 10},0.3\n4,999,10,10,0.3\n")
    code, _, err = cli("bundle", "adjust", d, "--start", "relative")
    assert code != 0
    assert "--start relative: 1 tie point(s) get no start value" in err and "999" in err


@pytest.mark.parametrize("fmt", ["bal", "bundler", "colmap-bin"])
def test_a_block_without_control_is_refused_before_the_orientations(sim, cli, tmp_path, fmt):
    # a BAL or Bundler file or a COLMAP model holds no control points: --start relative
    # oriented every pair of every strip first and then said 'absolute orientation of
    # strip 1 (...): 0 point(s) given, at least 3 needed (control points in the strips,
    # ...)', which such a file cannot give
    target = {"bal": tmp_path / "b.bal", "bundler": tmp_path / "b.out"}.get(fmt, tmp_path / "m")
    pg.bundle.write_block(sim.block, target, fmt, drop_extras=True)
    size = ("--image-size", "4000x3000") if fmt != "colmap-bin" else ()
    code, out, err = cli("bundle", "adjust", target, *size, "--start", "relative")
    assert code == 2 and out == ""
    assert "--start relative orients the strips to control points" in err
    assert "has 0 observed in its images" in err
    assert "leave out --start relative" in err and "--to csv" in err
    assert "absolute orientation" not in err


def test_the_library_refuses_fewer_than_three_control_points_first(sim):
    role = sim.block.role.copy()
    ctrl = np.flatnonzero(role == "control")
    role[ctrl[2:]] = "tie"  # two control points left
    block = sim.block.replace(role=role)
    strips = [sim.block.image_ids[:5].tolist(), sim.block.image_ids[5:].tolist()]
    with pytest.raises(pg.TooFewPointsError, match=r"control points observed in the strips' "
                       r"images: 2 point\(s\) given, at least 3 needed") as info:
        pg.bundle.start_from_relative_orientation(block, strips)
    assert info.value.have == 2 and info.value.need == 3


def test_the_json_says_where_the_start_values_came_from(sim, cli, tmp_path):
    # the summary's line (strips found in the file's order, control points) was missing
    # from --json, which said only "start": "relative"
    d = _without_start(sim, tmp_path / "b", columns=False)
    code, out, err = cli("bundle", "adjust", d, "--start", "relative", "--json")
    assert code == 0, err
    got = json.loads(out)["input"]
    assert got["start"] == "relative"
    ids = sim.block.image_ids.tolist()
    assert got["start_relative"] == {
        "strips": [ids], "strips_from": "file order", "control_points": 5, "bridged": []
    }
    code, out, err = cli(
        "bundle", "adjust", d, "--start", "relative", "--strips", f"{_ids(sim, 0)};{_ids(sim, 1)}",
        "--json",
    )
    assert code == 0, err
    got = json.loads(out)["input"]["start_relative"]
    assert got["strips"] == [ids[:5], ids[5:]] and got["strips_from"] == "--strips"
    assert all(type(i) is type(ids[0]) for s in got["strips"] for i in s)



@pytest.fixture(scope="module")
def near():
    """The block with GNSS/IMU start values (it converges in about 7 iterations)."""
    return pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=5)


def test_the_exit_of_a_run_not_converged_names_a_route_it_can_take(near, sim, cli, tmp_path):
    # the last line said 'else give better start values (--start relative for a block
    # without GNSS/IMU)' to a BAL file (no control points: --start relative is refused) and
    # to a run that started from --start relative already
    bal = tmp_path / "b.bal"
    pg.bundle.write_block(near.block, bal, "bal", drop_extras=True)
    code, out, err = cli("bundle", "adjust", bal, "--image-size", "4000x3000", "--datum",
                         "free", "--max-iterations", "1")  # fmt: skip
    assert code == 1, err
    last = err.strip().splitlines()[-1]
    assert "--start relative for a block without GNSS/IMU" not in last
    assert "--start relative needs 3 control points" in last and "the block has 0" in last
    assert "the block has 0 (BAL and Bundler files" in " ".join(out.split())  # the note
    d = _without_start(sim, tmp_path / "c", columns=False)
    code, _, err = cli("bundle", "adjust", d, "--start", "relative", "--max-iterations", "1")
    assert code == 1, err
    last = err.strip().splitlines()[-1]
    assert "else the start values came from relative orientations (--start relative) " in last
    assert "--start relative for a block without GNSS/IMU" not in last


def test_the_library_says_what_a_block_without_control_lacks(near, sim):
    lacks = "which needs 3 control points observed in the images, and the block has 0"
    tie = np.where(near.block.role == "check", "check", "tie")
    fit = pg.bundle_adjust(near.block.replace(role=tie), max_iterations=1, snooping=False)
    note = next(n for n in fit.notes if n.startswith("not converged"))
    assert lacks in note
    fit = pg.bundle_adjust(near.block, max_iterations=1, snooping=False)
    note = next(n for n in fit.notes if n.startswith("not converged"))
    assert "--start relative)" in note and "the block has" not in note
    tie = np.where(sim.block.role == "check", "check", "tie")  # 30 m, 20 deg off
    with pytest.raises(pg.DegenerateGeometryError, match="behind the camera") as info:
        pg.bundle_adjust(sim.block.replace(role=tie), datum="free")
    assert lacks in str(info.value)
