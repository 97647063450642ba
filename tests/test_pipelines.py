"""Chains of commands: the file one command writes is read right by the next."""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets

FIDUCIALS = datasets.path("lecture_fiducials")  # id,role,x,y,X,Y
TWO_IMAGES = datasets.path("lecture_two_images")  # id,x1,y1,x2,y2
LIDAR = datasets.path("lidar_wang2014")  # id,x,y,z,X,Y,Z


def _table(text: str) -> tuple[list[str], dict[str, list[float]]]:
    """(header, {id: coordinates}) of a point CSV written by photogeom (comments skipped)."""
    rows = list(csv.reader(io.StringIO("".join(
        line for line in text.splitlines(keepends=True) if not line.startswith("#")
    ))))  # fmt: skip
    header, body = rows[0], rows[1:]
    return header, {r[0]: [float(v) for v in r[1:] if v not in ("control", "check")] for r in body}


def _columns(path: Path, names: list[str]) -> dict[str, list[float]]:
    text = Path(path).read_text().splitlines(keepends=True)
    rows = csv.DictReader(io.StringIO("".join(ln for ln in text if not ln.startswith("#"))))
    return {r["id"]: [float(r[c]) for c in names] for r in rows}


# -- transform apply --inverse on the estimate's own file -----------------------------------


@pytest.mark.parametrize(
    "model, data, source, target",
    [
        ("similarity2d", FIDUCIALS, ["x", "y"], ["X", "Y"]),
        ("similarity3d", LIDAR, ["x", "y", "z"], ["X", "Y", "Z"]),
    ],
)
def test_inverse_reads_the_target_columns_of_a_file_with_both(cli, tmp_path, model, data,
                                                               source, target):
    """A file with x,y and X,Y: --inverse used to read x,y (the source coordinates) and map
    them as if they were targets (fiducial 1: (-16.99, -130.00) instead of (113.02, -0.00))."""
    params = tmp_path / "p.json"
    code, _, err = cli("transform", "estimate", model, data, "--output-params", params)
    assert code == 0, err
    code, out, err = cli("transform", "apply", params, data, "--inverse")
    assert code == 0, err
    header, got = _table(out)
    assert header[1 : 1 + len(source)] == source
    observed = _columns(data, source)
    for pid, xyz in observed.items():  # the inverse of the targets is near the sources
        np.testing.assert_allclose(got[pid][: len(source)], xyz, atol=0.2)
    # the forward direction reads the source columns, as before
    code, out, err = cli("transform", "apply", params, data)
    assert code == 0, err
    header, got = _table(out)
    assert header[1 : 1 + len(target)] == target
    for pid, xyz in _columns(data, target).items():
        np.testing.assert_allclose(got[pid][: len(target)], xyz, atol=0.2)


def test_inverse_with_cols_still_reads_the_named_columns(cli, tmp_path):
    params = tmp_path / "p.json"
    code, _, err = cli("transform", "estimate", "similarity2d", FIDUCIALS,
                       "--output-params", params)  # fmt: skip
    assert code == 0, err
    code, out, err = cli("transform", "apply", params, FIDUCIALS, "--inverse", "--cols", "x,y")
    assert code == 0, err
    assert "input" in out and "(x, y)" in out.splitlines()[0]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_recorded_columns_are_found_in_a_pipe(cli, tmp_path, fifo_read_once):
    """x2,y2 (no usual names) from a pipe: the fallback to the estimate's columns opened the
    input a second time and found it empty ('no coordinate columns found')."""
    params = tmp_path / "p.json"
    code, _, err = cli("transform", "estimate", "projective2d", TWO_IMAGES, "--source-cols",
                       "x2,y2", "--target-cols", "x1,y1", "--output-params", params)  # fmt: skip
    assert code == 0, err
    code, from_file, err = cli("transform", "apply", params, TWO_IMAGES)
    assert code == 0, err
    # a second opening of the pipe sees an empty stream instead of hanging
    fifo = fifo_read_once(Path(TWO_IMAGES).read_bytes(), "pts.pipe")
    code, from_pipe, err = cli("transform", "apply", params, fifo)
    assert code == 0, err
    assert _table(from_pipe) == _table(from_file)


# -- RPC text files keep the image size ------------------------------------------------------

RPC_DIR = Path(datasets.path("lecture_fiducials")).parent / "rpc"


@pytest.mark.parametrize("name", ["rpc_WV2.xml", "rpc_PLEIADES.xml"])
@pytest.mark.parametrize("style", ["ikonos", "lists"])
def test_rpc_text_round_trip_keeps_the_image_size(tmp_path, name, style):
    """write_rpc dropped the image size of an XML RPC: read back, WV2's image bounds became
    the normalised domain (cols -160..28368 instead of 0..28243) and its footprint moved."""
    from photogeom.rpc import read_rpc, write_rpc

    rpc = read_rpc(RPC_DIR / name)
    assert rpc.image_size is not None
    path = write_rpc(rpc, tmp_path / "out_RPC.TXT", style=style)
    back = read_rpc(path)
    assert back.same_as(rpc)
    assert back.image_size == rpc.image_size
    assert back.image_bounds == rpc.image_bounds
    np.testing.assert_array_equal(back.footprint(), rpc.footprint())


def test_rpc_text_without_image_size_writes_none(tmp_path):
    from photogeom.rpc import read_rpc, write_rpc

    rpc = read_rpc(RPC_DIR / "rpc_IKONOS.txt")
    path = write_rpc(rpc, tmp_path / "out_RPC.TXT")
    assert "NUM_COLUMNS" not in path.read_text()
    assert read_rpc(path).image_size is None


def test_rpc_text_image_size_needs_both_keys_and_whole_pixels(tmp_path):
    from photogeom import FileFormatError
    from photogeom.rpc import read_rpc, write_rpc

    text = write_rpc(read_rpc(RPC_DIR / "rpc_WV2.xml"), tmp_path / "a.rpc").read_text()
    one = tmp_path / "one.rpc"
    one.write_text("\n".join(ln for ln in text.splitlines() if "NUM_ROWS" not in ln) + "\n")
    with pytest.raises(FileFormatError, match="NUM_COLUMNS is given without NUM_ROWS"):
        read_rpc(one)
    half = tmp_path / "half.rpc"
    half.write_text(text.replace("NUM_ROWS: 20289", "NUM_ROWS: 20289.5"))
    with pytest.raises(FileFormatError, match=r"NUM_ROWS = 20289\.5 is not an image size"):
        read_rpc(half)


def test_rpc_refine_output_keeps_the_image_size(cli, tmp_path):
    """rpc refine WV2.xml ... -o: 'rpc info' of the written RPC said 'image size: not given'."""
    from photogeom.rpc import read_rpc

    rpc = read_rpc(RPC_DIR / "rpc_WV2.xml")
    cols = np.array([800.0, 27000.0, 14000.0, 2000.0, 25000.0, 9000.0])
    rows = np.array([900.0, 1500.0, 10000.0, 19000.0, 18500.0, 6000.0])
    h = np.array([10.0, 150.0, 80.0, 40.0, 120.0, 60.0])
    lon, lat = (np.asarray(v).tolist() for v in rpc.localize(cols, rows, h)[:2])
    gcp = tmp_path / "gcp.csv"
    gcp.write_text("id,lon,lat,h,col,row\n" + "".join(
        f"{k},{lon[k]!r},{lat[k]!r},{float(h[k])!r},{float(cols[k]) + 2.0!r},"
        f"{float(rows[k]) - 1.0!r}\n"
        for k in range(len(h))
    ))  # fmt: skip
    out = tmp_path / "refined_RPC.TXT"
    code, _, err = cli("rpc", "refine", RPC_DIR / "rpc_WV2.xml", gcp, "-o", out)
    assert code == 0, err
    code, info, err = cli("rpc", "info", out)
    assert code == 0, err
    assert "image size: 28244 x 20289 px" in info


def test_rpc_info_of_a_refined_rpc_names_a_missing_bias_error():
    """A refined RPC keeps ERR_RAND but drops ERR_BIAS: 'rpc info' printed 'bias None m'."""
    from dataclasses import replace

    from photogeom.rpc import read_rpc

    rpc = replace(read_rpc(RPC_DIR / "rpc_WV2.xml"), err_bias=None)
    text = rpc.summary()
    assert "vendor errors: bias not given, random 0.14 m" in text
    assert "None" not in text


# -- one concept, one name: aliases of options named differently by other commands -----------


def _ground_file(tmp_path: Path) -> Path:
    path = tmp_path / "ground.csv"
    path.write_text("id,X,Y,Z\nA,10.0,20.0,5.0\nB,-30.0,15.0,2.0\nC,5.0,-25.0,8.0\n")
    return path


def test_camera_project_takes_ground_cols_as_resection_does(cli, tmp_path):
    ground = _ground_file(tmp_path)
    args = ["camera", "project", ground, "--f", "153.2", "--eo", "0,0,1500,0,0,0"]
    code, plain, err = cli(*args, "--cols", "X,Y,Z")
    assert code == 0, err
    code, alias, err = cli(*args, "--ground-cols", "X,Y,Z")
    assert code == 0, err
    assert alias == plain
    code, _, err = cli(*args, "--ground-cols", "E,N,H")
    assert code == 2 and "choose others with --ground-cols" in err


def test_rpc_project_and_localize_take_the_column_names_of_rpc_fit(cli, tmp_path):
    rpc = RPC_DIR / "rpc_IKONOS.txt"
    pix = tmp_path / "pix.csv"
    pix.write_text("id,c,r,height\na,100,200,50\nb,3000,4000,120.5\n")
    code, ground, err = cli("rpc", "localize", rpc, pix, "--image-cols", "c,r,height")
    assert code == 0, err
    code, same, err = cli("rpc", "localize", rpc, pix, "--cols", "c,r,height")
    assert code == 0 and same == ground, err
    gfile = tmp_path / "ground.csv"
    gfile.write_text(ground.replace("id,lon,lat,h,", "id,LO,LA,HH,"))
    code, out, err = cli("rpc", "project", rpc, gfile, "--ground-cols", "LO,LA,HH")
    assert code == 0, err
    _, got = _table(out)
    np.testing.assert_allclose(got["a"], [100.0, 200.0], atol=1e-6)
    code, _, err = cli("rpc", "localize", rpc, pix, "--image-cols", "u,v")
    assert code == 2 and "choose others with --image-cols" in err


def test_crs_convert_takes_the_crs_option_names_of_cloud_transform(cli, tmp_path):
    geo = tmp_path / "geo.csv"
    geo.write_text("id,lon,lat,h\n1,9.5,48.1,300.25\n")
    code, plain, err = cli("crs", "convert", geo, "--from", "EPSG:4979", "--to", "EPSG:25832")
    assert code == 0, err
    code, alias, err = cli("crs", "convert", geo, "--from-crs", "EPSG:4979", "--to-crs",
                           "EPSG:25832")  # fmt: skip
    assert code == 0, err
    assert alias == plain
    code, _, err = cli("crs", "convert", geo, "--from-crs", "EPSG:99999", "--to-crs", "EPSG:25832")
    assert code == 2 and err.startswith("error: --from-crs:")


def test_grid_fit_takes_sigma_as_bundle_adjust_does(cli, tmp_path):
    rng = np.random.default_rng(3)
    uv = rng.uniform(0, 400, (60, 2))
    res = rng.normal(0, 0.3, (60, 2))
    csv_file = tmp_path / "res.csv"
    csv_file.write_text("image_id,u,v,rx,ry\n" + "".join(
        f"1,{float(a)!r},{float(b)!r},{float(c)!r},{float(d)!r}\n"
        for (a, b), (c, d) in zip(uv, res)
    ))  # fmt: skip
    base = ["grid", "fit", csv_file, "--image-size", "401x401", "--spacing", "200", "--json"]
    code, _, err = cli(*base, "-o", tmp_path / "a.json", "--sigma-obs", "0.3")
    assert code == 0, err
    code, _, err = cli(*base, "-o", tmp_path / "b.json", "--sigma", "0.3")
    assert code == 0, err
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()
    code, _, err = cli(*base, "-o", tmp_path / "c.json", "--sigma", "-1")
    assert code == 2 and "--sigma must be positive" in err


def test_bundle_report_takes_report_as_bundle_adjust_does(cli, tmp_path):
    code, _, err = cli("bundle", "report", tmp_path / "none.json", "--report",
                       tmp_path / "no" / "r.html")  # fmt: skip
    assert code == 2 and "--report: cannot write" in err


# -- write_points writes only ids that read_points gives back ---------------------------------


@pytest.mark.parametrize("bad", ["b\nc", "b\r\nc", "b\r"])
def test_write_points_refuses_ids_that_would_not_read_back(tmp_path, bad):
    """An id with a line break was written quoted over two lines, which read_points refuses
    ('a quoted field cannot span lines')."""
    from photogeom import InputError
    from photogeom.io import write_points

    out = tmp_path / "p.csv"
    with pytest.raises(InputError, match="holds a line break"):
        write_points(out, ["a", bad], np.zeros((2, 2)), ["x", "y"])
    assert not out.exists()


def test_write_points_round_trips_awkward_ids_exactly(tmp_path):
    from photogeom.io import read_points, write_points

    ids = ["007", "a,b", 'q"x', "#c", "é", "7.0", "-", "nan", "x;y", "in ner"]
    xyz = np.array([[0.1, -0.0, 5e-324], [1e308, -1e-310, 2.5e-8], [1 / 3, 2 / 3, 1e22]] * 3
                   + [[np.pi, np.e, -1.0]])  # fmt: skip
    path = write_points(tmp_path / "p.csv", ids, xyz, ["x", "y", "z"])
    back = read_points(path, "x,y,z")
    assert list(back.ids) == ids
    assert np.array_equal(back.coords, xyz) and np.signbit(back.coords[0, 1])


# -- cloud transform labels its output as transform apply does ------------------------------


@pytest.fixture
def lidar_clouds(tmp_path):
    pytest.importorskip("laspy")
    import photogeom as pg

    rng = np.random.default_rng(4)
    scan = rng.uniform([-60.0, -10.0, -5.0], [0.0, 60.0, 10.0], (500, 3))
    src = tmp_path / "scan.las"
    pg.io.write_cloud(src, scan, scales=(1e-3, 1e-3, 1e-3))
    return src


def _cloud_crs(cli, path) -> str:
    code, out, err = cli("cloud", "info", path, "--json")
    assert code == 0, err
    import json

    return json.loads(out)["crs"]


def test_cloud_transform_inverse_drops_a_crs_the_points_leave(cli, tmp_path, lidar_clouds):
    """Parameters recording the target CRS only (orient absolute --target-crs): 'cloud
    transform --inverse' of a cloud in that CRS labelled the scan-frame result EPSG:25832
    (the input's record), while 'transform apply --inverse' writes no CRS."""
    params = tmp_path / "oa.json"
    code, _, err = cli("orient", "absolute", LIDAR, "--target-crs", "EPSG:25832",
                       "--output-params", params)  # fmt: skip
    assert code == 0, err
    utm = tmp_path / "utm.las"
    code, _, err = cli("cloud", "transform", lidar_clouds, utm, "--params", params, "-q")
    assert code == 0, err
    assert "25832" in str(_cloud_crs(cli, utm))
    back = tmp_path / "back.las"
    code, _, err = cli("cloud", "transform", utm, back, "--params", params, "--inverse", "-q")
    assert code == 0, err
    assert _cloud_crs(cli, back) is None
    code, out, err = cli("transform", "apply", params, LIDAR, "--inverse")
    assert code == 0 and "# crs:" not in out, err
    # --crs still names it when the user knows it
    named = tmp_path / "named.las"
    code, _, err = cli("cloud", "transform", utm, named, "--params", params, "--inverse", "-q",
                       "--crs", "EPSG:32632")  # fmt: skip
    assert code == 0, err
    assert "32632" in str(_cloud_crs(cli, named))


def test_cloud_transform_forward_with_only_a_source_crs(cli, tmp_path, lidar_clouds):
    """Parameters recording the source CRS only: the cloud in that CRS was written with its
    record unchanged, though its points are now in the target system."""
    params = tmp_path / "oa.json"
    code, _, err = cli("orient", "absolute", LIDAR, "--source-crs", "EPSG:25832",
                       "--output-params", params)  # fmt: skip
    assert code == 0, err
    import photogeom as pg

    labelled = tmp_path / "in.las"
    pts = pg.io.read_cloud_xyz(lidar_clouds)
    pg.io.write_cloud(labelled, pts, scales=(1e-3, 1e-3, 1e-3), crs="EPSG:25832")
    out = tmp_path / "out.las"
    code, _, err = cli("cloud", "transform", labelled, out, "--params", params, "-q")
    assert code == 0, err
    assert _cloud_crs(cli, out) is None


def test_cloud_transform_without_crs_records_keeps_the_input_record(cli, tmp_path, lidar_clouds):
    """No CRS in the parameters: the input's record is kept, as documented."""
    params = tmp_path / "t.json"
    code, _, err = cli("transform", "estimate", "similarity3d", LIDAR, "--output-params", params)
    assert code == 0, err
    import photogeom as pg

    labelled = tmp_path / "in.las"
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    pg.io.write_cloud(labelled, pts, scales=(1e-3, 1e-3, 1e-3), crs="EPSG:25832")
    out = tmp_path / "out.las"
    code, _, err = cli("cloud", "transform", labelled, out, "--params", params, "-q")
    assert code == 0, err
    assert "25832" in str(_cloud_crs(cli, out))


def test_grid_report_takes_report_as_grid_fit_does(cli, tmp_path):
    code, _, err = cli("grid", "report", "--preset", "FC300S", "--report",
                       tmp_path / "no" / "r.html")  # fmt: skip
    assert code == 2 and "--report: cannot write" in err


def test_forward_reads_the_source_columns_col_row_beside_x_y(cli, tmp_path):
    """--source-cols col,row --target-cols x,y and a file holding both: the forward apply read
    x,y (the first usual names) as pixels (mark 1: (-111.11, 91.84) instead of (-100, 100))."""
    pts = tmp_path / "fid.csv"
    pts.write_text("id,col,row,x,y\n1,10,20,-100.0,100.0\n2,1990,20,100.0,100.0\n"
                   "3,1990,1980,100.0,-100.0\n4,10,1980,-100.0,-100.0\n5,1000,1000,0.01,0.0\n")
    params = tmp_path / "p.json"
    code, _, err = cli("transform", "estimate", "affine2d", pts, "--source-system", "pixel",
                       "--target-system", "fiducial", "--source-cols", "col,row",
                       "--target-cols", "x,y", "--output-params", params)  # fmt: skip
    assert code == 0, err
    code, out, err = cli("transform", "apply", params, pts)
    assert code == 0, err
    header, got = _table(out)
    assert header == ["id", "x", "y"]
    np.testing.assert_allclose(got["1"], [-100.0, 100.0], atol=0.01)
    code, out, err = cli("transform", "apply", params, pts, "--inverse")
    assert code == 0, err
    header, got = _table(out)
    assert header == ["id", "col", "row"]
    np.testing.assert_allclose(got["3"], [1990.0, 1980.0], atol=0.05)


# -- bundle adjust labels lengths in the unit of the block's CRS ----------------------------


def test_bundle_adjust_unit_follows_the_crs_and_survives_the_written_block(cli, tmp_path):
    """bundle adjust --crs EPSG:2263 (US feet) labelled its lengths 'm' (JSON 'unit': 'm'
    beside crs_name '... (ftUS)'), where orient absolute and transform estimate take the
    unit of the CRS; the block written with -o records the CRS, so its re-adjustment too."""
    import json

    blk = tmp_path / "blk"
    code, _, err = cli("bundle", "simulate", blk, "--strips", "2", "--images-per-strip", "3",
                       "--tie-points-per-image", "60", "--seed", "2")  # fmt: skip
    assert code == 0, err
    adjusted = tmp_path / "adj"
    code, out, err = cli("bundle", "adjust", blk, "--crs", "EPSG:2263", "--json", "-o", adjusted)
    assert code == 0, err
    assert json.loads(out)["unit"] == "ftUS"
    code, out, err = cli("bundle", "adjust", adjusted, "--json")
    assert code == 0, err
    assert json.loads(out)["unit"] == "ftUS"
    code, out, err = cli("bundle", "adjust", adjusted, "--json", "--unit", "usft")
    assert code == 0 and json.loads(out)["unit"] == "usft", err
    code, out, err = cli("bundle", "adjust", blk, "--json")  # no CRS: metres, as before
    assert code == 0 and json.loads(out)["unit"] == "m", err
