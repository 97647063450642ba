"""The command line under odd input: values a computation cannot give a number for, option
values that are refused, output names that are no file. Each command either does its job or
stops with one ``error:`` line and exit code 2, and prints or writes nothing half-done."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import photogeom as pg

IKONOS = pg.datasets.path("ikonos")


def _strict_json(text: str):
    """``json.loads`` refusing the NaN and Infinity tokens that JSON does not have."""

    def refuse(token):
        raise AssertionError(f"{token} in JSON output")

    return json.loads(text, parse_constant=refuse)


def test_rpc_project_json_writes_null_where_the_projection_has_no_number(cli, tmp_path):
    # a height of 1e308 m overflows the cubic terms of the RPC: the projection is NaN, which
    # the CSV writes as nan and JSON (no NaN) must write as null; it used to stop with a
    # ValueError traceback ("Out of range float values are not JSON compliant")
    lonlath = np.array([[-56.17, -34.90, 30.0], [-56.16, -34.91, 1e308]])
    pts = tmp_path / "g.csv"
    pts.write_text("id,lon,lat,h\np1,-56.17,-34.9,30.0\np2,-56.16,-34.91,1e308\n")
    rpc = pg.RPC.from_file(IKONOS)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the RPC's extrapolation warning
        col, row = rpc.project(*lonlath.T)
    assert np.isfinite(col[0]) and np.isnan(col[1])  # the premise: one point has no pixel
    code, out, err = cli("rpc", "project", IKONOS, pts, "--json")
    assert code == 0, err
    assert "Traceback" not in err
    points = _strict_json(out)["points"]
    assert [p["id"] for p in points] == ["p1", "p2"]
    np.testing.assert_allclose([points[0]["col"], points[0]["row"]], [col[0], row[0]], atol=1e-9)
    assert points[1]["col"] is None and points[1]["row"] is None
    # the CSV of the same run says nan for the same point
    code, out, _ = cli("rpc", "project", IKONOS, pts)
    assert code == 0 and out.splitlines()[-1] == "p2,nan,nan"



def _fiducials_params(cli, tmp_path):
    params = tmp_path / "p.json"
    fid = pg.datasets.path("lecture_fiducials")
    code, _, err = cli("transform", "estimate", "similarity2d", fid, "--output-params", params)
    assert code == 0, err
    return fid, params


def test_dash_output_of_a_printing_command_is_the_standard_output(cli, tmp_path, monkeypatch):
    # '-o -' wrote a file named '-' in the current folder ("wrote 8 point(s) to -"), where a
    # command line means the standard output, which these commands print to without -o
    fid, params = _fiducials_params(cli, tmp_path)
    monkeypatch.chdir(tmp_path)
    code, printed, err = cli("transform", "apply", params, fid)
    assert code == 0, err
    for cmd in (("transform", "apply", params, fid), ("crs", "convert", fid, "--from",
                "EPSG:32632", "--to", "EPSG:32632", "--cols", "x,y")):  # fmt: skip
        code, out, err = cli(*cmd, "-o", "-")
        assert code == 0, err
        assert not (tmp_path / "-").exists()
        if cmd[0] == "transform":
            assert out == printed and out.count("\n") == 1 + 1 + 8  # comment, header, rows


def test_dash_for_an_output_that_is_a_file_or_folder_is_refused(cli, tmp_path, monkeypatch):
    fid = pg.datasets.path("lecture_fiducials")
    grids = tmp_path / "g.json"  # not read: the refusal comes first
    monkeypatch.chdir(tmp_path)
    cases = [
        (("transform", "estimate", "similarity2d", fid, "--report", "-"), "--report -", "file"),
        (("transform", "estimate", "similarity2d", fid, "--output-params", "-"),
         "--output-params -", "file"),
        (("orient", "absolute", pg.datasets.path("lidar_wang2014"), "--report", "-"),
         "--report -", "file"),
        (("bundle", "simulate", "-", "--strips", "2", "--images-per-strip", "3"), "OUTPUT -",
         "folder"),
        (("grid", "correct-images", grids, tmp_path, "-"), "DST_DIR -", "folder"),
        (("examples", "run", "fiducials", "--report", "-"), "--report -", "file"),
    ]  # fmt: skip
    for args, named, kind in cases:
        code, out, err = cli(*args)
        assert code == 2, (args, err)
        assert err.startswith(f"error: {named}: this output is written to a {kind}"), err
        assert f"give a {kind} name" in err and len(err.strip().splitlines()) == 1
        assert out == ""
        assert not (tmp_path / "-").exists(), args


def test_out_cols_that_the_readers_would_refuse_are_refused(cli, tmp_path):
    # '--out-cols a,a' and '--out-cols id,b' wrote headers 'id,a,a' and 'id,id,b' (exit 0),
    # files that every point reader refuses ("column name(s) a appear more than once")
    fid, params = _fiducials_params(cli, tmp_path)  # columns id, role, x, y, X, Y
    apply = ("transform", "apply", params, fid, "--cols", "x,y")
    convert = ("crs", "convert", fid, "--from", "EPSG:32632", "--to", "EPSG:32632", "--cols",
               "x,y")  # fmt: skip
    for cmd in (apply, convert):
        for names, fault in (("a,a", "a named more than once"), ("id,b", "id is already"),
                             ("b,role", "role is already")):  # fmt: skip
            out_csv = tmp_path / "out.csv"
            code, out, err = cli(*cmd, "--out-cols", names, "-o", out_csv)
            assert code == 2 and out == "", (cmd, names, err)
            assert err.startswith("error: --out-cols: ") and fault in err, err
            assert not out_csv.exists()
        # names the readers take: written, and read back by the same reader
        code, _, err = cli(*cmd, "--out-cols", "E,N", "-o", tmp_path / "ok.csv")
        assert code == 0, err
        table = pg.io.read_points(tmp_path / "ok.csv", ["E", "N"])
        assert list(table.ids) == [str(i) for i in range(1, 9)]


def test_a_streamed_job_that_stops_at_its_first_block_prints_nothing(cli, tmp_path):
    # the comment and header lines were printed before the error (a script's '> out.csv'
    # kept a header-only file beside exit code 2): '--tol 0', a NaN on line 3
    pixels = tmp_path / "px.csv"
    pixels.write_text("id,col,row,h\np1,6000,5000,30\np2,6100,5100,31\n")
    for args in (("--tol", "0"), ("--max-iter", "0")):
        code, out, err = cli("rpc", "localize", IKONOS, pixels, *args)
        assert code == 2 and err.startswith(f"error: {args[0]} ") and out == "", (args, err)
    bad = tmp_path / "bad.csv"
    bad.write_text("id,col,row,h\np1,6000,5000,30\np2,6100,nan,31\n")
    code, out, err = cli("rpc", "localize", IKONOS, bad)
    assert code == 2 and "line 3" in err and out == ""
    # a job without rows still prints its comments and header, and a good one is unchanged
    empty = tmp_path / "empty.csv"
    empty.write_text("id,col,row,h\n")
    code, out, _ = cli("rpc", "localize", IKONOS, empty)
    assert code == 0 and out.splitlines()[-1] == "id,lon,lat,h,status"
    code, out, _ = cli("rpc", "localize", IKONOS, pixels)
    lines = out.splitlines()
    assert code == 0 and lines[-3] == "id,lon,lat,h,status" and lines[-1].startswith("p2,")


def test_point_writer_to_a_stream_writes_nothing_before_its_rows():
    import io

    from photogeom.io import PointWriter

    buf = io.BytesIO()
    try:
        with PointWriter(None, ["x", "y"], comments=["c"], stream=buf):
            raise RuntimeError("the first block failed")
    except RuntimeError:
        pass
    assert buf.getvalue() == b""
    with PointWriter(None, ["x", "y"], comments=["c"], stream=buf) as w:
        w.write(["a"], np.array([[1.0, 2.5]]))
    assert buf.getvalue() == b"# c\nid,x,y\na,1.0,2.5\n"


def test_correct_images_names_a_file_given_as_the_image_folder(cli, tmp_path):
    # a file as SRC_DIR was reported as "input folder F does not exist", though it exists
    grids = tmp_path / "g.json"
    res = tmp_path / "r.csv"
    rows = [f"a,{u},{v},0.1,-0.1" for u in range(50, 1000, 100) for v in range(50, 800, 100)]
    res.write_text("image_id,u,v,rx,ry\n" + "\n".join(rows) + "\n")
    code, _, err = cli("grid", "fit", res, "--image-size", "1000x800", "--spacing", "500",
                       "--folds", "0", "-o", grids)  # fmt: skip
    assert code == 0, err
    code, out, err = cli("grid", "correct-images", grids, res, tmp_path / "out")
    assert code == 2 and out == ""
    assert err == f"error: input folder {res} is a file, not a folder: give the folder that " \
        "holds the images\n"  # fmt: skip
    assert not (tmp_path / "out").exists()
    code, _, err = cli("grid", "correct-images", grids, tmp_path / "none", tmp_path / "out")
    assert code == 2 and err == f"error: input folder {tmp_path / 'none'} does not exist\n"


def test_pixel_without_pixel_geometry_is_explained_in_options(cli, tmp_path):
    # '--pixel' with a camera given by --f alone said "set origin_px ..., e.g. with
    # InteriorOrientation.digital(...)": Python words, no option to use
    ground = tmp_path / "g.csv"
    ground.write_text("id,X,Y,Z\n1,990,1010,5\n2,1020,980,0\n")
    eo = ("--eo", "1000,1000,1500,0,0,0")
    code, out, err = cli("camera", "project", ground, "--f", "152", *eo, "--pixel")
    assert code == 2 and out == "" and len(err.splitlines()) == 1
    assert "InteriorOrientation" not in err and "--principal-point COL,ROW" in err, err
    assert "--pixel-size" in err and "leave out --pixel" in err
    # the advice works: the principal point at pixel (5000, 4000) with 10 um pixels puts the
    # nadir point (1000, 1000) there and a point 10 m east 152 / 1500 * 10 mm = 100 px right
    ground.write_text("id,X,Y,Z\n1,1000,1000,0\n2,1010,1000,0\n")
    code, out, err = cli("camera", "project", ground, "--f", "152", *eo, "--pixel",
                         "--principal-point", "5000,4000", "--pixel-size", "0.01")  # fmt: skip
    assert code == 0, err
    rows = [r.split(",") for r in out.splitlines() if r[:2] in ("1,", "2,")]
    np.testing.assert_allclose(np.array(rows, dtype=float)[:, 1:],
                               [[5000, 4000], [5000 + 152 / 1500 * 10 / 0.01, 4000]],
                               atol=1e-6)  # fmt: skip


def test_grid_apply_names_an_empty_image_id_without_a_grid(cli, tmp_path):
    # a row with an empty image_id said "no grid in g.json for image(s) " and named nothing
    res = tmp_path / "r.csv"
    rows = [f"a,{u},{v},0.1,-0.1" for u in range(50, 1000, 100) for v in range(50, 800, 100)]
    res.write_text("image_id,u,v,rx,ry\n" + "\n".join(rows) + "\n")
    grids = tmp_path / "g.json"
    code, _, err = cli("grid", "fit", res, "--image-size", "1000x800", "--spacing", "500",
                       "--folds", "0", "-o", grids)  # fmt: skip
    assert code == 0, err
    obs = tmp_path / "o.csv"
    obs.write_text("image_id,u,v\na,10,10\n,20,20\na,30,30\n")
    out_csv = tmp_path / "out.csv"
    code, out, err = cli("grid", "apply", grids, obs, "-o", out_csv)
    assert code == 2 and out == "" and not out_csv.exists()
    assert err == (f"error: {obs}: no grid in {grids} for image(s) '' (first row: line 3); fit "
                   "their grids with photogeom grid fit, or remove their rows\n")  # fmt: skip


def test_an_unknown_image_key_is_refused(cli, tmp_path):
    # '--image-key bogus' ran (exit 0) on a CSV block and stopped with Python words
    # ("image_key must be 'name' or 'id'") on a COLMAP model; it is a choice of two now
    blk = tmp_path / "blk"
    small = ("--strips", "2", "--images-per-strip", "3", "--tie-points-per-image", "20")
    code, _, err = cli("bundle", "simulate", blk, *small, "--gcps", "none", "--checks", "0")
    assert code == 0, err
    for cmd in (("adjust", blk), ("convert", blk, tmp_path / "b.bal", "--drop-extras")):
        code, out, err = cli("bundle", *cmd, "--image-key", "bogus")
        assert code == 2 and out == "", (cmd, err)
        assert "Invalid value for '--image-key'" in err and "'name', 'id'" in err, err
    assert not (tmp_path / "b.bal").exists()
    colmap = tmp_path / "colmap"
    code, _, err = cli("bundle", "convert", blk, colmap, "--to", "colmap", "--drop-extras")
    assert code == 0, err
    code, out, err = cli("bundle", "convert", colmap, tmp_path / "back", "--to", "csv",
                         "--image-key", "id", "--json")  # fmt: skip
    assert code == 0, err
    assert _strict_json(out)["images"] == 6


def test_bundle_simulate_refuses_in_the_words_of_its_options(cli, tmp_path):
    # '--terrain bogus' said "terrain must be ... or a callable Z(X, Y)", '--gsd nan' "gsd /
    # flying_height must be > 0, got nan / nan", '--gcps bogus' offered "an (n, 2) array":
    # Python words and values no command line can give
    out_dir = tmp_path / "blk"
    cases = [
        (("--terrain", "bogus"), "error: --terrain must be 'flat' or 'hilly', got 'bogus'"),
        (("--gsd", "nan"), "error: --gsd must be a positive number of metres per pixel, got nan"),
        (("--gsd", "-0.01"), "error: --gsd must be a positive number of metres per pixel"),
        (("--gcps", "bogus"), "error: --gcps: unknown layout 'bogus'; use 'corners', "),
        (("--checks", "-1"), "error: --checks: unknown layout '-1'; use 'corners', "),
    ]
    for args, start in cases:
        code, out, err = cli("bundle", "simulate", out_dir, *args)
        assert code == 2 and out == "" and err.startswith(start), (args, err)
        for python in ("callable", "flying_height", "array", "terrain="):
            assert python not in err, (args, err)
        assert not out_dir.exists()
    code, _, err = cli("bundle", "simulate", out_dir, "--checks", "bogus")
    assert err.rstrip().endswith("or a count of points at random positions (0 or more)")


# --- garbage lines through the point readers of the command line -------------------------------

_GARBAGE = st.lists(
    st.one_of(
        st.text(alphabet='0123456789.,;"# \t-+eEnaifé\ufeff\r', max_size=12),
        st.sampled_from(["a,nan,1", "a,1,inf", "7;1,5;2", '"p,1', "id,x,y", "#", ""]),
    ),
    min_size=1,
    max_size=3,
)


@pytest.fixture(scope="module")
def garbage_models(tmp_path_factory):
    """The parameter file of ``transform apply`` and the grids file of ``grid apply``, made
    once for the garbage-line test."""
    from photogeom.cli.main import main

    tmp = tmp_path_factory.mktemp("models")
    params = tmp / "p.json"
    params.write_text(json.dumps({"model_parameters": pg.Similarity2D(1.0, 0.1, 5.0, -2.0)
                                  .to_dict()}))  # fmt: skip
    res = tmp / "r.csv"
    res.write_text("image_id,u,v,rx,ry\n" + "\n".join(
        f"a,{u},{v},0.1,-0.1" for u in range(50, 400, 100) for v in range(50, 400, 100)
    ) + "\n")  # fmt: skip
    grids = tmp / "g.json"
    try:
        main(["grid", "fit", str(res), "--image-size", "400x400", "--spacing", "200",
              "--folds", "0", "-o", str(grids)])  # fmt: skip
    except SystemExit as done:
        assert done.code in (0, None)
    return {
        "transform apply": ("transform", "apply", params),
        "grid apply": ("grid", "apply", grids),
        "rpc localize": ("rpc", "localize", IKONOS),
    }


_GOOD_LINES = {
    "transform apply": ["id,x,y", "1,0.5,1.5", "2,3,4", "3,-1,2.25"],
    "grid apply": ["image_id,u,v", "a,10,20", "a,200.5,100", "a,300,399"],
    "rpc localize": ["id,col,row,h", "p1,6000,5000,30", "p2,6100,5100,31", "p3,100,200,20"],
}


@settings(
    max_examples=12,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(
    garbage=_GARBAGE,
    where=st.integers(min_value=0, max_value=5),
    encoding=st.sampled_from(["utf-8", "utf-8-sig", "latin-1"]),
    command=st.sampled_from(sorted(_GOOD_LINES)),
)
def test_garbage_lines_give_a_result_or_one_error_line(
    cli, tmp_path_factory, garbage_models, garbage, where, encoding, command
):
    # any line a spreadsheet or an editor may leave in a point CSV: the command either works
    # (exit 0) or stops with one 'error:' line (exit 2), never a traceback, and a failed run
    # leaves no output file and no temporary file
    tmp = tmp_path_factory.mktemp("garbage")
    lines = list(_GOOD_LINES[command])
    lines[where % (len(lines) + 1):where % (len(lines) + 1)] = garbage
    pts = tmp / "pts.csv"
    pts.write_bytes("\n".join(lines).encode(encoding, errors="replace") + b"\n")
    out_csv = tmp / "out.csv"
    code, _, err = cli(*garbage_models[command], pts, "-o", out_csv)
    assert code in (0, 2), err
    assert "Traceback" not in err
    if code == 2:
        assert err.startswith("error: ") and len(err.strip().splitlines()) == 1, err
        assert not out_csv.exists()
    else:
        assert out_csv.exists()
    assert not [p.name for p in tmp.iterdir() if p.name.startswith(".")]


def test_rpc_project_refuses_lon_lat_columns_read_in_a_cartesian_crs(cli, tmp_path):
    # columns lon, lat, h with --crs EPSG:32721 were read as easting, northing in metres:
    # pixels four million pixels off the image (exit 0, an extrapolation warning only)
    pts = tmp_path / "g.csv"
    pts.write_text("id,lon,lat,h\np1,-56.17,-34.9,30.0\n")
    for crs in ("EPSG:32721", "enu:-34.9,-56.1,0"):
        code, out, err = cli("rpc", "project", IKONOS, pts, "--crs", crs)
        assert code == 2 and out == "", err
        assert err.startswith(f"error: {pts}: columns lon, lat, h hold longitude and latitude, "
                              f"but --crs {crs} has Cartesian coordinates")  # fmt: skip
    lined = tmp_path / "lined.csv"
    lined.write_text("# crs: EPSG:32721\n" + pts.read_text())
    code, out, err = cli("rpc", "project", IKONOS, lined)
    assert code == 2 and "but the file's CRS EPSG:32721 has Cartesian" in err
    assert "correct the file's '# crs:' line" in err and "leave --crs out" not in err
    # a geographic --crs takes them
    code, out, err = cli("rpc", "project", IKONOS, pts, "--crs", "EPSG:4979", "--json")
    assert code == 0, err
    col, row = pg.RPC.from_file(IKONOS).project(-56.17, -34.9, 30.0)
    got = _strict_json(out)["points"][0]
    np.testing.assert_allclose([got["col"], got["row"]], [col, row], atol=1e-6)


def test_crs_convert_refuses_lon_lat_columns_in_a_cartesian_crs(cli, tmp_path):
    # 'crs convert g.csv --from EPSG:32721 --to EPSG:4979' with columns lon,lat,h read the
    # degrees as metres and wrote lon -147.2, lat -85.5 for a point at -56.17, -34.9 (exit 0)
    pts = tmp_path / "g.csv"
    pts.write_text("id,lon,lat,h\np1,-56.17,-34.9,30.0\n")
    out_csv = tmp_path / "out.csv"
    code, out, err = cli("crs", "convert", pts, "--from", "EPSG:32721", "--to", "EPSG:4979",
                         "-o", out_csv)  # fmt: skip
    assert code == 2 and out == "" and not out_csv.exists()
    assert err.startswith(f"error: {pts}: columns lon, lat, h hold longitude and latitude, but "
                          "its CRS EPSG:32721 has Cartesian coordinates (x, y, z); give the CRS "
                          "of the points with --from (e.g. --from EPSG:4979)")  # fmt: skip
    lined = tmp_path / "lined.csv"
    lined.write_text("# crs: enu:-34.9,-56.1,0\n" + pts.read_text())
    code, _, err = cli("crs", "convert", lined, "--to-crs", "EPSG:4979")
    assert code == 2 and "correct the file's '# crs:' line" in err
    # with the CRS of the points the same file converts, and back again to the same numbers
    code, out, err = cli("crs", "convert", pts, "--from", "EPSG:4979", "--to", "EPSG:32721",
                         "-o", out_csv)  # fmt: skip
    assert code == 0, err
    code, out, err = cli("crs", "convert", out_csv, "--to", "EPSG:4979")
    assert code == 0, err
    np.testing.assert_allclose([float(v) for v in out.splitlines()[-1].split(",")[1:]],
                               [-56.17, -34.9, 30.0], atol=1e-9)  # fmt: skip
