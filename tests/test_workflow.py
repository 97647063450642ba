"""Workflows: files written by one command read back by the next."""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.io import read_points, write_points


def test_ids_beginning_with_hash_survive_a_write_and_read(tmp_path):
    """An id such as '#12' written unquoted made its row a comment line: the point was
    silently lost by the next command (camera project -> orient resection)."""
    ids = ["# 1", "#2", " #3", "007", "P 3"]
    coords = np.arange(15, dtype=float).reshape(5, 3)
    path = tmp_path / "pts.csv"
    write_points(path, ids, coords, columns=("X", "Y", "Z"))
    back = read_points(path)
    assert list(back.ids) == ["# 1", "#2", "#3", "007", "P 3"]
    np.testing.assert_array_equal(back.coords, coords)
    assert '"#2"' in path.read_text()


class _Result:
    def __init__(self, exit_code: int, output: str) -> None:
        self.exit_code, self.output = exit_code, output


def _run(args):
    """Run the command line as ``photogeom`` does (errors -> 'error:' line, exit code 2)."""
    import contextlib
    import io

    from photogeom.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    code = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([str(a) for a in args])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
    return _Result(code, out.getvalue() + err.getvalue())


def test_transform_apply_names_output_columns_as_the_estimate(tmp_path):
    """A pixel -> mm interior orientation (--source-cols col,row --target-cols x,y) applied to
    pixel points wrote mm coordinates as columns COL,ROW, which orient resection (x,y) could
    not read; the output now has the estimate's target columns (source ones with --inverse)."""
    fid = tmp_path / "fid.csv"
    fid.write_text(
        "id,col,row,x,y\n"
        "1,19018.3,9674.8,113.016,0.002\n2,185.6,9675.2,-112.977,-0.002\n"
        "3,9601.4,259.2,0.013,112.99\n4,9601.0,19092.3,0.008,-113.008\n"
    )
    params = tmp_path / "io.json"
    r = _run(["transform", "estimate", "similarity2d", fid, "--source-cols", "col,row",
              "--target-cols", "x,y", "--source-system", "pixel", "--target-system", "fiducial",
              "--unit", "mm", "--output-params", params])  # fmt: skip
    assert r.exit_code == 0, r.output
    pix = tmp_path / "pix.csv"
    pix.write_text("id,col,row\n007,100.5,200.25\n")
    out = tmp_path / "mm.csv"
    assert _run(["transform", "apply", params, pix, "-o", out]).exit_code == 0
    table = read_points(out)
    assert table.columns == ("x", "y") and table.ids == ("007",)
    back = tmp_path / "back.csv"
    assert _run(["transform", "apply", params, out, "--inverse", "-o", back]).exit_code == 0
    again = read_points(back)
    assert again.columns == ("col", "row")
    np.testing.assert_allclose(again.coords, [[100.5, 200.25]], atol=1e-9)


def test_missing_columns_name_the_option_of_the_command(tmp_path):
    """Every command's 'column(s) ... not found' error advised '--source-cols x,y', an option
    of transform estimate only (orient resection has --image-cols, transform apply --cols)."""
    bad = tmp_path / "bad.csv"
    bad.write_text("id,COL,ROW\n1,1.0,2.0\n2,3.0,4.0\n3,5.0,7.0\n")
    ground = tmp_path / "ground.csv"
    ground.write_text("id,X,Y,Z\n1,0,0,0\n2,1,0,0\n3,0,1,0\n")
    cases = [
        (["orient", "resection", ground, bad, "--f", "152"], "--image-cols"),
        (["orient", "resection", bad, bad, "--f", "152"], "--ground-cols"),
        (["camera", "project", bad, "--f", "152", "--eo", "0,0,9,0,0,0"], "--cols"),
        (["transform", "estimate", "similarity2d", bad, "--target-cols", "x,y"], "--target-cols"),
        (["orient", "relative", bad, "--f", "100"], "--cols"),
    ]
    for args, option in cases:
        r = _run(args)
        assert r.exit_code == 2, (args, r.output)
        assert f"choose others with {option})" in r.output, (args, r.output)
        assert "--source-cols" not in r.output


def test_grid_fit_and_apply_read_files_with_comment_lines(tmp_path):
    """grid fit / grid apply took the first line as the header even when it was a '#'
    comment, so the observations.csv of a block folder (written with '# pixels: ...') was
    refused: "no column 'image_id' (columns: # pixels: centre ...)". Comments are skipped
    as in every other point file, kept in the output of grid apply, and a line number in an
    error is still the file's."""
    rng = np.random.default_rng(7)
    n = 60
    u, v = rng.uniform(0, 400, n), rng.uniform(0, 300, n)
    rx, ry = rng.normal(0, 0.3, n), rng.normal(0, 0.3, n)
    head = "# pixels: centre of the top-left pixel at (0, 0), u right, v down\n"
    res = tmp_path / "res.csv"
    res.write_text(
        head + "image_id,point_id,u,v,rx,ry\n"
        + "".join(f"#1,{k},{u[k]},{v[k]},{rx[k]},{ry[k]}\n" for k in range(n))
        .replace("#1,", '"#1",')
    )  # fmt: skip
    grids = tmp_path / "g.json"
    r = _run(["grid", "fit", res, "--image-size", "400x300", "--spacing", "100",
              "-o", grids, "--folds", "0"])  # fmt: skip
    assert r.exit_code == 0, r.output
    obs = tmp_path / "obs.csv"
    obs.write_text(head + "image_id,u,v\n" + '"#1",100.0,100.0\n')
    out = tmp_path / "out.csv"
    r = _run(["grid", "apply", grids, obs, "-o", out])
    assert r.exit_code == 0, r.output
    text = out.read_text().splitlines()
    assert text[0] == head.strip() and text[1] == "image_id,u,v"
    assert text[2].startswith('"#1",')
    bad = tmp_path / "bad.csv"
    bad.write_text(head + "image_id,u,v\n" + '"#1",100.0,x\n')
    r = _run(["grid", "apply", grids, bad])
    assert r.exit_code == 2 and "line 3, column v" in r.output, r.output


def test_crs_convert_reads_lon_lat_h_without_cols(tmp_path):
    """rpc localize writes lon,lat,h with a '# crs: EPSG:4979' line; crs convert, whose help
    says the columns are found by name, refused it: 'no coordinate columns found'."""
    pyproj = pytest.importorskip("pyproj")
    geo = tmp_path / "ground.csv"
    geo.write_text("# crs: EPSG:4979\nid,lon,lat,h,status\n007,9.0,48.0,500.0,converged\n")
    out = tmp_path / "utm.csv"
    r = _run(["crs", "convert", geo, "--to", "EPSG:32632", "-o", out])
    assert r.exit_code == 0, r.output
    table = read_points(out)
    assert table.ids == ("007",)
    t = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:32632", always_xy=True)
    np.testing.assert_allclose(table.coords[0], t.transform(9.0, 48.0, 500.0), atol=1e-6)


def test_cloud_register_json_without_check_pairs(tmp_path):
    """cloud register --json with the default --check-every 0 ended in a traceback (exit 1):
    the per-axis check statistics were lists of NaN, which the JSON writer refuses."""
    laspy = pytest.importorskip("laspy")
    rng = np.random.default_rng(0)
    xyz = rng.uniform(0, 50, (200, 3))
    paths = []
    for name, pts in (("a.las", xyz), ("b.las", xyz + np.array([100.0, 200.0, 5.0]))):
        header = laspy.LasHeader(point_format=3, version="1.2")
        header.scales, header.offsets = [0.001] * 3, [0.0] * 3
        las = laspy.LasData(header)
        las.x, las.y, las.z = pts.T
        las.write(tmp_path / name)
        paths.append(tmp_path / name)
    r = _run(["cloud", "register", *paths, "--json"])
    assert r.exit_code == 0, r.output
    import json

    d = json.loads(r.output)
    assert d["n_check"] == 0 and d["check_rms"] == [None, None, None]
    np.testing.assert_allclose(d["translation"], [100.0, 200.0, 5.0], atol=1e-3)


def test_library_warnings_are_one_cli_line(tmp_path, capsys):
    """A photogeom warning in a command printed Python's display (the library's source file
    and line, 'SuspectResultWarning:') and Python words ('see fit.snooping()', 'try
    initial='); it is now one line 'warning: ...' naming the command's options."""
    import warnings

    from photogeom.cli import main as cli_main
    from photogeom.errors import SuspectResultWarning

    shown = []
    before = warnings.showwarning
    cli_main._show_warning(
        lambda *a: shown.append(a), cli_main.NumericWarnings(),
        SuspectResultWarning("bad (see fit.snooping()), (try initial= from another source)"),
        SuspectResultWarning, "resection.py", 1,
    )  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert err.startswith("warning: bad (see the w-test of the residuals)")
    assert "--initial X0,Y0,Z0,OMEGA,PHI,KAPPA" in err and "resection.py" not in err
    cli_main._show_warning(
        lambda *a: shown.append(a), cli_main.NumericWarnings(), UserWarning("x"), UserWarning,
        "f.py", 2,
    )  # fmt: skip
    assert len(shown) == 1  # other warnings: Python's display
    assert warnings.showwarning is before


def test_camera_dlt_estimate_output_is_a_camera_file(tmp_path):
    """camera dlt estimate --output-params writes the decomposed camera under 'orientation',
    but camera project / orient intersection --camera refused the file ('no camera found');
    they now read that orientation (angles in the file's unit)."""
    import photogeom as pg
    from photogeom.camera import ExteriorOrientation, InteriorOrientation

    rng = np.random.default_rng(5)
    ground = np.c_[rng.uniform(0, 600, 12), rng.uniform(0, 600, 12), rng.uniform(0, 80, 12)]
    io = InteriorOrientation(f=152.0)
    eo = ExteriorOrientation(300.0, 280.0, 1500.0, 0.02, -0.03, 0.5)
    image = pg.project(ground, io, eo)
    ids = [f"0{k}" for k in range(12)]
    g, im = tmp_path / "g.csv", tmp_path / "im.csv"
    write_points(g, ids, ground, columns=("X", "Y", "Z"))
    write_points(im, ids, image, columns=("x", "y"))
    params = tmp_path / "dlt.json"
    r = _run(["camera", "dlt", "estimate", g, im, "--output-params", params,
              "--angle-unit", "gon"])  # fmt: skip
    assert r.exit_code == 0, r.output
    out = tmp_path / "proj.csv"
    r = _run(["camera", "project", g, "--camera", params, "-o", out])
    assert r.exit_code == 0, r.output
    np.testing.assert_allclose(read_points(out).coords, image, atol=1e-8)


def test_bundle_adjust_arcsec_with_a_csv_block_output(tmp_path):
    """bundle adjust -o DIR --angle-unit arcsec (offered by --help) adjusted the block and
    then stopped with "error: angle_unit must be deg, gon or rad, not 'arcsec'", writing
    nothing; the angles are now shown in arcsec and the block written in degrees, which the
    next adjustment reads. bundle convert to CSV writes deg for arcsec too (it
    refused the unit bundle adjust accepts)."""
    block = tmp_path / "sim"
    r = _run(["bundle", "simulate", block, "--strips", "2", "--images-per-strip", "3",
              "--tie-points-per-image", "30", "--no-imu"])  # fmt: skip
    assert r.exit_code == 0, r.output
    out = tmp_path / "adj"
    r = _run(["bundle", "adjust", block, "-o", out, "--angle-unit", "arcsec", "--no-snooping"])
    assert r.exit_code == 0, r.output
    assert "omega_deg" in (out / "images.csv").read_text().splitlines()[1]
    assert _run(["bundle", "adjust", out, "--no-snooping"]).exit_code == 0
    r = _run(["bundle", "convert", block, tmp_path / "c", "--to", "csv", "--angle-unit", "arcsec"])
    assert r.exit_code == 0, r.output
    assert "omega_deg" in (tmp_path / "c" / "images.csv").read_text().splitlines()[1]


def test_transform_apply_reads_the_columns_of_the_estimate(tmp_path):
    """transform estimate --source-cols x2,y2 --target-cols x1,y1 --output-params, then
    transform apply on the same kind of file: 'no coordinate columns found ... (or name the
    columns to use)'. apply now reads the estimate's source columns (target ones with
    --inverse) when the file has them, and the error names --cols."""
    pts = tmp_path / "two.csv"
    pts.write_text(
        "id,x1,y1,x2,y2\n1,253,64,175,44\n2,40,389,18,176\n3,300,300,210,190\n"
        "4,120,30,80,15\n5,60,200,30,100\n"
    )
    params = tmp_path / "p.json"
    r = _run(["transform", "estimate", "affine2d", pts, "--source-cols", "x2,y2",
              "--target-cols", "x1,y1", "--output-params", params])  # fmt: skip
    assert r.exit_code == 0, r.output
    out = tmp_path / "out.csv"
    assert _run(["transform", "apply", params, pts, "-o", out]).exit_code == 0
    assert out.read_text().splitlines()[1] == "id,x1,y1"
    back = tmp_path / "back.csv"
    assert _run(["transform", "apply", params, out, "--inverse", "-o", back]).exit_code == 0
    assert back.read_text().splitlines()[1] == "id,x2,y2"  # image 1 -> image 2 coordinates
    xy2 = read_points(back, "x2,y2").coords[:2]
    np.testing.assert_allclose(xy2, [[175, 44], [18, 176]], atol=1e-9)
    bad = tmp_path / "bad.csv"
    bad.write_text("id,a,b\n1,2,3\n")
    r = _run(["transform", "apply", params, bad])
    assert r.exit_code == 2 and "(or name them with --cols)" in r.output, r.output


def test_crs_convert_to_geographic_feeds_rpc_project(tmp_path):
    """crs convert --to EPSG:4979 wrote lon, lat, h as columns x,y,z, which rpc project (it
    looks for lon,lat,h) refused: 'cannot find the ground (lon, lat, h) columns'."""
    pyproj = pytest.importorskip("pyproj")
    t = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:32721", always_xy=True)
    e, n, h = t.transform(-56.17, -34.90, 30.0)
    utm = tmp_path / "utm.csv"
    utm.write_text(f"# crs: EPSG:32721\nid,x,y,z\n007,{e!r},{n!r},{h!r}\n")
    geo = tmp_path / "geo.csv"
    r = _run(["crs", "convert", utm, "--to", "EPSG:4979", "-o", geo])
    assert r.exit_code == 0, r.output
    assert "id,lon,lat,h" in geo.read_text().splitlines()
    from photogeom.datasets import path

    rpc = path("lecture_fiducials").parent / "rpc" / "rpc_IKONOS.txt"
    r = _run(["rpc", "project", rpc, geo])
    assert r.exit_code == 0, r.output
    assert "id,col,row" in r.output and "007," in r.output
