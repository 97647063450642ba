"""Command line: `photogeom orient relative` (one CSV or two joined by id, pixels, --json,
--report, --output, errors)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg

IO = pg.InteriorOrientation(100.0, unit="mm")
E1 = pg.ExteriorOrientation(0.0, 0.0, 100.0, 0.02, -0.03, 0.01)
E2 = pg.ExteriorOrientation(60.0, 3.0, 101.0, -0.01, 0.02, 0.05)


def _csv(header, ids, *arrays):
    rows = np.column_stack(arrays)
    return (
        header
        + "\n"
        + "".join(f"{i}," + ",".join(repr(float(v)) for v in r) + "\n" for i, r in zip(ids, rows))
    )


@pytest.fixture
def matches(tmp_path):
    rng = np.random.default_rng(0)
    pts = np.column_stack(
        [rng.uniform(-30, 90, 40), rng.uniform(-40, 40, 40), rng.uniform(-10, 10, 40)]
    )
    xy1 = pg.project(pts, IO, E1) + rng.normal(0, 0.004, (40, 2))
    xy2 = pg.project(pts, IO, E2) + rng.normal(0, 0.004, (40, 2))
    xy2[5] += [0.8, -1.2]  # a wrong match
    ids = [f"P{i}" for i in range(40)]
    one = tmp_path / "matches.csv"
    one.write_text(_csv("id,x1,y1,x2,y2", ids, xy1, xy2))
    f1, f2 = tmp_path / "img1.csv", tmp_path / "img2.csv"
    f1.write_text(_csv("id,x,y", ids, xy1))
    f2.write_text(_csv("id,x,y", ids[:39], xy2[:39]) + "Q1,0.0,0.0\n")
    return one, f1, f2, xy1, xy2


def test_relative_json_matches_the_library(cli, matches):
    one, _, _, xy1, xy2 = matches
    code, out, err = cli("orient", "relative", one, "--f", "100", "--sigma", "0.004", "--json")
    assert code == 0, err
    data = json.loads(out)
    fit = pg.relative_orientation(xy1, xy2, IO, sigma=0.004, ids=[f"P{i}" for i in range(40)])
    for k, v in fit.params.items():
        assert data["parameters"][k]["value"] == pytest.approx(v, abs=1e-12)
    assert data["flagged"] == ["P5"]
    assert data["parallax"]["worst"][0] == "P5"
    assert data["model_parameters"]["exterior2"]["X0"] == 1.0
    assert data["model_parameters"]["exterior2"]["angle_unit"] == "deg"


def test_relative_two_files_report_and_model_points(cli, matches, tmp_path):
    _, f1, f2, _, _ = matches
    rep, model = tmp_path / "ro.html", tmp_path / "model.csv"
    code, out, err = cli(
        "orient", "relative", f1, f2, "--f", "100", "--method", "independent",
        "--angle-unit", "gon", "--report", rep, "--output", model,
    )  # fmt: skip
    assert code == 0, err
    assert "phi1" in out and "y-parallaxes" in out and "P5" in out
    assert "ids in only one file" in out and "P39" in out and "Q1" in out
    html = rep.read_text()
    assert "<img" in html and "Worst y-parallaxes" in html
    t = pg.io.read_points(model, ["X", "Y", "Z"])
    assert len(t.ids) == 38 and "P5" not in t.ids


def test_relative_pixels(cli, tmp_path):
    io = pg.InteriorOrientation.digital(1000.0, 500.0, 350.0, unit="px")
    rng = np.random.default_rng(1)
    pts = np.column_stack(
        [rng.uniform(-30, 90, 30), rng.uniform(-30, 30, 30), rng.uniform(-10, 10, 30)]
    )
    c1 = io.image_to_pixel(pg.project(pts, io, E1))
    c2 = io.image_to_pixel(pg.project(pts, io, E2))
    f = tmp_path / "px.csv"
    f.write_text(_csv("id,col1,row1,col2,row2", range(30), c1, c2))
    code, out, err = cli(
        "orient", "relative", f, "--f", "1000", "--unit", "px", "--principal-point", "500,350",
        "--pixel", "--json",
    )  # fmt: skip
    assert code == 0, err
    data = json.loads(out)
    R = E2.matrix @ E1.matrix.T
    p = {k: v["value"] for k, v in data["parameters"].items()}
    assert np.allclose(pg.opk_matrix(p["omega2"], p["phi2"], p["kappa2"]), R, atol=1e-9)


def test_relative_errors(cli, matches, tmp_path):
    one, _, _, _, _ = matches
    code, _, err = cli("orient", "relative", one)
    assert code == 2 and "--f" in err
    few = tmp_path / "few.csv"
    few.write_text("id,x1,y1,x2,y2\n1,0,0,1,0\n2,1,1,2,1\n3,2,0,3,0\n4,0,2,1,2\n")
    code, _, err = cli("orient", "relative", few, "--f", "100")
    assert code == 2 and "at least 5" in err
    code, _, err = cli("orient", "relative", one, "--f", "100", "--cols", "a,b")
    assert code == 2 and "--cols" in err


def test_output_cameras_intersect_the_model_points_again(cli, matches, tmp_path):
    """--output-cameras writes the two cameras in the model system; orient intersection
    with them finds the model points of --output (an independent computation: a space
    intersection of the image files, not the relative orientation's own triangulation)."""
    _, f1, f2, _, _ = matches
    c1, c2, model = tmp_path / "c1.json", tmp_path / "c2.json", tmp_path / "model.csv"
    code, _, err = cli(
        "orient", "relative", f1, f2, "--f", "100", "--sigma", "0.004", "-o", model,
        "--output-cameras", c1, c2,
    )  # fmt: skip
    assert code == 0, err
    cam1, cam2 = json.loads(c1.read_text()), json.loads(c2.read_text())
    assert cam1["image"] == 1 and cam2["model_unit"] == "bx"
    assert cam2["exterior"]["X0"] == 1.0 and cam1["exterior"]["X0"] == 0.0
    code, out, err = cli(
        "orient", "intersection", f1, f2, "--camera", c1, "--camera", c2, "--sigma", "0.004"
    )
    assert code == 0, err
    rows = {
        ln.split(",")[0]: [float(v) for v in ln.split(",")[1:4]]
        for ln in out.splitlines()
        if ln and not ln.startswith("#") and not ln.startswith("id")
    }
    ref = {
        ln.split(",")[0]: [float(v) for v in ln.split(",")[1:4]]
        for ln in model.read_text().splitlines()
        if ln and not ln.startswith("#") and not ln.startswith("id")
    }
    common = sorted(set(rows) & set(ref))
    assert len(common) >= 35
    np.testing.assert_allclose([rows[k] for k in common], [ref[k] for k in common], atol=1e-9)
    code, _, err = cli(
        "orient", "relative", f1, f2, "--f", "100", "--output-cameras", c1, c1
    )
    assert code == 2 and "--output-cameras: give two different files" in err


def test_ambiguous_five_points_name_no_option_the_command_lacks(cli, tmp_path):
    """Five tie points with several exact relative orientations: the library asks for start
    values (initial=), which the command has no option for; the message says where they
    can be given instead."""
    rng = np.random.default_rng(0)
    for _ in range(40):
        pts = np.column_stack(
            [rng.uniform(-30, 90, 5), rng.uniform(-40, 40, 5), rng.uniform(-10, 10, 5)]
        )
        xy1, xy2 = pg.project(pts, IO, E1), pg.project(pts, IO, E2)
        try:
            pg.relative_orientation(xy1, xy2, IO)
        except pg.DegenerateGeometryError as exc:
            if "(initial=)" in str(exc):
                break
    else:
        pytest.fail("no ambiguous five-point case drawn")
    path = tmp_path / "five.csv"
    path.write_text(_csv("id,x1,y1,x2,y2", [f"P{i}" for i in range(5)], xy1, xy2))
    code, _out, err = cli("orient", "relative", str(path), "--f", "100")
    assert code != 0
    assert "(initial=)" not in err and "photogeom.relative_orientation(..., initial=)" in err


def test_parallax_figure_of_many_matches_is_thinned():
    """The y-parallax figure drew every one of 3300 matches (a solid blob) and scaled the
    arrows to the longest; it now draws 3000 (the 600 longest always), says "3000 of 3300
    shown", follows the 90th percentile of the lengths, and the scale arrow's label is its
    true length."""
    from matplotlib.quiver import Quiver, QuiverKey

    from photogeom.cli.orient_relative import _parallax_figure
    from photogeom.report.plots import LONGEST_ALWAYS_SHOWN, MAX_ARROWS

    rng = np.random.default_rng(6)
    n = 3300
    pts = np.column_stack(
        [rng.uniform(-30, 90, n), rng.uniform(-40, 40, n), rng.uniform(-10, 10, n)]
    )
    xy1 = pg.project(pts, IO, E1) + rng.normal(0, 0.004, (n, 2))
    xy2 = pg.project(pts, IO, E2) + rng.normal(0, 0.004, (n, 2))
    fit = pg.relative_orientation(xy1, xy2, IO, sigma=0.004)
    used = np.asarray(fit.inliers)
    fig = _parallax_figure(fit, xy1)
    (ax,) = fig.axes
    (q,) = [c for c in ax.collections if isinstance(c, Quiver)]  # nothing clipped
    assert q.N == MAX_ARROWS
    title = ax.get_title(loc="left")
    assert f"arrows: {MAX_ARROWS} of {int(used.sum())} shown" in title and "clipped" not in title
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert f"used ({MAX_ARROWS} of {int(used.sum())} shown)" in legend
    # the longest parallaxes are among the drawn arrows
    py = np.abs(np.asarray(fit.parallax))[used]
    drawn = np.sort(np.hypot(q.U, q.V))[::-1]
    assert np.allclose(drawn[:LONGEST_ALWAYS_SHOWN], np.sort(py)[::-1][:LONGEST_ALWAYS_SHOWN])
    # the scale follows the 90th percentile; its arrow's label is its length
    width = abs(np.diff(ax.get_xlim())[0])
    assert np.median(py) / q.scale / width > 0.015
    (key,) = [a for a in ax.artists if isinstance(a, QuiverKey)]
    p90 = np.quantile(py, 0.9)
    assert key.text.get_text() == f"{key.U:g} mm" and 0.4 * p90 <= key.U <= p90
