"""The HTML reports as documents to hand in (the numbers of the printed tables
and the JSON, units, scales of the figures, inputs named, outputs refused early)."""

from __future__ import annotations

import html
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from html_tables import table_rows

W, H = 300, 200


@pytest.fixture(scope="module")
def residual_csv(tmp_path_factory):
    rng = np.random.default_rng(5)
    lines = ["image_id,u,v,rx,ry"]
    for im in ("IMG_1", "IMG_2"):
        uv = np.column_stack([rng.uniform(0, W - 1, 300), rng.uniform(0, H - 1, 300)])
        r = np.column_stack([np.sin(uv[:, 0] / 80), np.cos(uv[:, 1] / 60)])
        r += rng.normal(0, 0.1, r.shape)
        lines += [f"{im},{a:.4f},{b:.4f},{c:.5f},{d:.5f}" for a, b, c, d in np.c_[uv, r]]
    p = tmp_path_factory.mktemp("grid") / "residuals.csv"
    p.write_text("\n".join(lines) + "\n")
    return p


def test_grid_fit_report_shows_the_printed_numbers(cli, residual_csv, tmp_path):
    # before: the report showed the reductions as fractions under the label "reduction"
    # (0.8556808414 where the printed table and its reader see "85.6 %") and sigma0 and
    # the RMS values to 10 digits; it did not name the node spacing
    args = ("grid", "fit", residual_csv, "--image-size", f"{W}x{H}", "--spacing", "50")
    code, text, err = cli(*args, "-o", tmp_path / "g.npz", "--json")
    assert code == 0, err
    stats = json.loads(text)["images"]
    rep = tmp_path / "r.html"
    code, printed, err = cli(*args, "-o", tmp_path / "g.npz", "--report", rep)
    assert code == 0, err
    page = rep.read_text(encoding="utf-8")
    rows = table_rows(page)
    for image, s in stats.items():
        row = rows[image]
        assert row[4:9] == [
            f"{s['sigma0']:.4f}",
            f"{s['rms_before']:.4f}",
            f"{s['rms_after']:.4f}",
            f"{100 * s['reduction']:.1f} %",
            f"{100 * s['reduction_cv']:.1f} %",
        ]
        assert f"{100 * s['reduction']:.1f} %" in printed
    assert "RMS before [px]" in rows["image"] and "50 px node spacing" in page


def test_grid_fit_report_figure_has_a_scale_arrow(residual_csv, monkeypatch):
    # before: the mean grid was drawn "not to scale": arrows of an automatic length and no
    # scale arrow, so the figure gave no size of the correction
    from matplotlib.quiver import QuiverKey

    from photogeom.calibration import fit_grids
    from photogeom.cli import grid as grid_cli
    from photogeom.report import html as report_html

    rng = np.random.default_rng(1)
    uv = np.column_stack([rng.uniform(0, W - 1, 400), rng.uniform(0, H - 1, 400)])
    r = np.column_stack([0.5 + 0 * uv[:, 0], -0.25 + 0 * uv[:, 1]])
    grids = fit_grids({"a": (uv, r)}, (W, H), 50.0, folds=0)
    figures = []
    real = report_html.figure_to_png

    def keep(fig, dpi=110):
        figures.append(fig)
        return real(fig, dpi)

    monkeypatch.setattr(report_html, "figure_to_png", keep)
    page = grid_cli._report_html(grids)
    (fig,) = figures
    (ax,) = fig.axes
    keys = [a for a in ax.artists if isinstance(a, QuiverKey)]
    assert len(keys) == 1 and keys[0].text.get_text() == "0.5 px"
    assert "[px]" in ax.get_xlabel() and "[px]" in ax.get_ylabel()
    assert "arrows x" in ax.get_title(loc="left") and "scale arrow" in page


def test_grid_report_reductions_in_per_cent_as_grid_evaluate_prints_them(cli, tmp_path):
    # before: the block table showed "reduction 0.3358452321" beside "34 %" in the summary
    # of the same report, and 'grid evaluate' prints "33.6 %"; every number to 10 digits
    common = ("--preset", "FC300S", "--strips", "1", "--images-per-strip", "4")
    code, printed, err = cli("grid", "evaluate", *common, "--spacing", "1000")
    assert code == 0, err
    out = tmp_path / "r.html"
    code, _, err = cli(
        "grid", "report", *common, "--spacing", "1000", "--spacings", "500,1000", "-o", out
    )
    assert code == 0, err
    rows = table_rows(out.read_text(encoding="utf-8"))
    for label, printed_label in (
        ("RMS (px)", "RMS"),
        ("mean length (px)", "mean length"),
        ("mean step (GSD)", "mean step"),
    ):
        line = next(x for x in printed.splitlines() if re.search(rf"│ +{printed_label} │", x))
        assert [c.strip() for c in line.split("│")[2:5]] == rows[label][:3]
    assert rows["FC300S"][3] == rows["RMS (px)"][2]  # the summary: the same reduction
    assert all(re.fullmatch(r"\d+\.\d{4}", c) for c in rows["0"])  # per image, px


def test_relative_report_prints_the_w_of_the_console_and_the_model_orientations(cli, tmp_path):
    # before: the report's worst y-parallaxes had w to 3 significant digits ("195", "1.7")
    # where the console prints "194.94", "1.70", the critical value 3.29 beside the 3.291 of
    # the residual table above it, and the report lacked the orientation of the images in
    # the model system that the console prints
    import photogeom as pg

    io = pg.InteriorOrientation(100.0, unit="mm")
    e1 = pg.ExteriorOrientation(0.0, 0.0, 100.0, 0.02, -0.03, 0.01)
    e2 = pg.ExteriorOrientation(60.0, 3.0, 101.0, -0.01, 0.02, 0.05)
    rng = np.random.default_rng(0)
    pts = rng.uniform([-30, -40, -10], [90, 40, 10], (40, 3))
    xy1 = pg.project(pts, io, e1) + rng.normal(0, 0.004, (40, 2))
    xy2 = pg.project(pts, io, e2) + rng.normal(0, 0.004, (40, 2))
    xy2[5] += [0.8, -1.2]  # a wrong match: a large w
    src = tmp_path / "m.csv"
    lines = [f"P{i}," + ",".join(map(repr, map(float, r))) for i, r in enumerate(np.c_[xy1, xy2])]
    src.write_text("id,x1,y1,x2,y2\n" + "\n".join(lines) + "\n")
    rep = tmp_path / "ro.html"
    code, out, err = cli("orient", "relative", src, "--f", "100", "--sigma", "0.004",
                         "--report", rep)  # fmt: skip
    assert code == 0, err
    page = rep.read_text(encoding="utf-8")
    rows = table_rows(page)
    printed = {
        m.group(1): m.group(2)
        for m in re.finditer(r"^  (P\d+) +\S+ +(\S+) +(?:used|left out)$", out, flags=re.M)
    }
    assert len(printed) == 10
    for pid, w in printed.items():
        assert rows[pid][1] == w
    assert "critical value of the w-test: 3.291" in page
    for line in out.splitlines():
        if "in the model system:" in line:
            assert html.escape(line) in page


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (("examples", "run", "--all"), "--report"),
        (("orient", "relative", "MATCHES", "--f", "100"), "--report"),
        (("orient", "relative", "MATCHES", "--f", "100"), "--output-cameras"),
        (("transform", "estimate", "similarity2d", "FIDUCIALS"), "--output-params"),
        (("orient", "absolute", "LIDAR"), "--report"),
        (("camera", "dlt", "estimate", "MATCHES"), "--report"),
    ],
)
def test_unwritable_report_refused_before_the_computation(cli, tmp_path, args, option):
    # before: these commands computed first (examples run --all: every example, half a
    # minute) and then failed on the write with "cannot write ...", not naming the option
    import photogeom.datasets as ds

    files = {
        "MATCHES": tmp_path / "no_such_input.csv",  # refused before the input is read
        "FIDUCIALS": ds.path("lecture_fiducials"),
        "LIDAR": ds.path("lidar_wang2014"),
    }
    argv = [files.get(a, a) for a in args]
    missing = tmp_path / "no_folder" / "out.html"
    if option == "--output-cameras":
        argv += [option, tmp_path / "c1.json", missing]
    else:
        argv += [option, missing]
    code, out, err = cli(*argv)
    assert code == 2
    assert err.startswith(f"error: {option}: cannot write {missing}") and "does not exist" in err
    assert "ok" not in out  # no example ran
    code, out, err = cli(*argv[:-1], tmp_path)  # a folder
    assert code == 2 and f"{option}: cannot write {tmp_path}: it is a folder" in err
    below_a_file = tmp_path / "plain.txt"
    below_a_file.write_text("x")
    code, out, err = cli(*argv[:-1], below_a_file / "out.html")
    assert code == 2 and f"{below_a_file} is a file, not a folder" in err


def test_reports_name_the_command_line_that_made_them(cli, tmp_path):
    # before: the reports of orient absolute, camera dlt estimate and grid fit named no input
    # file at all, and no report named the options (method, units, convention, sigmas)
    import photogeom.datasets as ds
    from photogeom.report import Report

    lidar = ds.path("lidar_wang2014")
    rep = tmp_path / "a b.html"  # quoted in the line
    args = ("orient", "absolute", lidar, "--method", "gauss-helmert", "--sigma-source",
            "0.01", "--angle-unit", "gon", "--report", rep)  # fmt: skip
    code, _, err = cli(*args)
    assert code == 0, err
    page = rep.read_text(encoding="utf-8")
    line = f"photogeom orient absolute {lidar} --method gauss-helmert --sigma-source 0.01 "
    line += f"--angle-unit gon --report '{rep}'"
    assert f"command: <code>{html.escape(line)}</code>" in page
    assert "command:" not in Report("made in Python").to_html()


def test_bundle_report_of_a_saved_record_names_the_adjustment(cli, tmp_path):
    block = tmp_path / "blk"
    code, _, err = cli("bundle", "simulate", block, "--preset", "FC300S", "--strips", "1",
                       "--images-per-strip", "3", "--tie-points-per-image", "30")  # fmt: skip
    assert code == 0, err
    record = tmp_path / "r.json"
    code, _, err = cli("bundle", "adjust", block, "--free", "f", "--result", record)
    assert code == 0, err
    assert json.loads(record.read_text())["command"].endswith(f"--free f --result {record}")
    out = tmp_path / "again.html"
    code, _, err = cli("bundle", "report", record, "-o", out)
    assert code == 0, err
    rows = table_rows(out.read_text(encoding="utf-8"))
    assert rows["adjusted by"] == [f"photogeom bundle adjust {block} --free f --result {record}"]


def test_bundle_report_summary_has_the_digits_of_the_printed_summary(cli, tmp_path):
    # before: the report rounded sigma0 to 4 significant digits (3.138) where the printed
    # summary gives 4 decimals (3.1383), the RMS residual 0.3606 beside 0.361, the IMU
    # residuals 1.147 beside 1.15, the critical value 3.291 beside 3.29, |w| 91.53 beside
    # 91.5, and the check-point RMSE only to 4 decimals of a metre (0.0081 for 0.008068)
    block = tmp_path / "blk"
    code, _, err = cli("bundle", "simulate", block, "--preset", "FC300S", "--strips", "2",
                       "--images-per-strip", "4", "--blunders", "2", "--seed", "3")  # fmt: skip
    assert code == 0, err
    rep = tmp_path / "b.html"
    code, out, err = cli("bundle", "adjust", block, "--report", rep)
    assert code == 0, err
    rep_text = rep.read_text(encoding="utf-8")
    page = html.unescape(re.sub(r"<[^>]+>", " ", rep_text))
    rows = table_rows(rep.read_text(encoding="utf-8"))
    sigma0 = re.search(r"sigma0 a posteriori (\S+) \(a priori", out).group(1)
    assert rows["sigma0 a posteriori"] == [sigma0]
    rms = re.search(r"RMS (\S+) px; GSD", out).group(1)
    assert rows["RMS image residual"] == [f"{rms} px"]
    imu = re.search(r"IMU residuals .*?: (omega .* deg)", out).group(1)
    assert any(v == [imu] for k, v in rows.items() if k.startswith("RMS IMU residual"))
    check = re.search(r"check points \(\d+\), [^:]*: RMSE (X \S+, Y \S+, Z \S+) m \(([^)]*)\)", out)
    assert f"RMSE {check.group(1)} m ({check.group(2)};" in page
    crit = re.search(r"critical (\S+)\)", out).group(1)
    assert f"critical value {crit}:" in page
    flagged = re.findall(r"image (\S+) point (\S+): \|w\| = (\S+)", out)
    assert flagged
    for image, point, w in flagged:
        assert re.search(rf"<tr><td>{image}</td><td>{point}</td><td[^>]*>{w}</td>", str(rep_text))


def _tables(text: str) -> list[list[list[str]]]:
    """Every table of an HTML report as rows of cell texts."""
    out = []
    for table in re.findall(r"<table[^>]*>(.*?)</table>", text, flags=re.S):
        rows = []
        for row in re.findall(r"<tr>(.*?)</tr>", table, flags=re.S):
            rows.append(
                [
                    html.unescape(re.sub(r"<[^>]+>", "", c)).strip()
                    for c in re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", row, flags=re.S)
                ]
            )
        out.append(rows)
    return out


def test_absolute_compare_report_has_the_printed_digits(cli, tmp_path):
    # before: the console cut wide cells ("-1424.5862…", "8071.83065…": digits lost) and
    # the report printed the same numbers to 10 significant digits (0.3108127688 where the
    # console printed 3.11e-01, 710.0829971 us beside 710.1)
    import photogeom.datasets as ds

    rep = tmp_path / "c.html"
    code, out, err = cli("orient", "absolute", ds.path("kraus_absolute_orientation"),
                         "--compare", "--angle-unit", "gon", "--report", rep)  # fmt: skip
    assert code == 0, err
    assert "…" not in out
    printed = {}
    for line in out.splitlines():
        words = line.split()
        if words and words[0] in ("closed-form", "svd", "gauss-markov", "gauss-helmert"):
            printed.setdefault(words[0], []).append(words[1:])
    params, diffs = _tables(rep.read_text(encoding="utf-8"))[:2]
    for table, k in ((params, 0), (diffs, 1)):
        for row in table[1:]:
            if row[0] in printed:
                assert printed[row[0]][k][:-1 if k else None] == row[1:-1 if k else None]
    assert any(re.fullmatch(r"\d\.\d\de[-+]\d\d", c) for c in diffs[1][1:4])


def test_cloud_register_console_and_report_show_the_same_parameters(cli, tmp_path):
    # before: the console printed the translation to 4 decimals (479999.9999), kappa to 6
    # (40.107021) and the standard deviations to 3 digits (0.000115) where the report's
    # table shows 479999.999912, 40.1070207 and 0.00011; the report gave sigma0 no unit
    import photogeom as pg

    rng = np.random.default_rng(8)
    x = rng.uniform([0, 0, 0], [400, 300, 30], (1500, 3))
    t = pg.Similarity3D.from_angles(1.00004, 0.01, -0.02, 0.7, [480000.0, 5300000.0, 250.0])
    src, dst = tmp_path / "scan.las", tmp_path / "ref.las"
    pg.io.write_cloud(src, x, scales=(1e-5,) * 3)
    pg.io.write_cloud(dst, t.apply(x) + rng.normal(0, 0.01, x.shape), scales=(1e-5,) * 3,
                      crs="EPSG:32633")  # fmt: skip
    rep = tmp_path / "r.html"
    code, out, err = cli("cloud", "register", src, dst, "--check-every", "10", "--scheduler",
                         "sync", "--report", rep)  # fmt: skip
    assert code == 0, err
    rows = table_rows(rep.read_text(encoding="utf-8"))
    tr = re.search(r"translation (\S+), (\S+), (\S+) m\n  std. dev. (\S+), (\S+), (\S+) m", out)
    for k, name in enumerate(("tx", "ty", "tz")):
        assert rows[name][:2] == [tr.group(1 + k), tr.group(4 + k)]
    ang = re.search(r"omega (\S+) deg  phi (\S+) deg  kappa (\S+) deg", out)
    sd = re.search(r"std. dev. (\S+) / (\S+) / (\S+) deg", out)
    for k, name in enumerate(("omega", "phi", "kappa")):
        assert rows[name][:2] == [ang.group(1 + k), sd.group(1 + k)]
    assert rows["scale"][:2] == list(re.search(r"scale (\S+) \+- (\S+)", out).groups())
    sigma0 = re.search(r"sigma0 (\S+) m", out).group(1)
    assert rows["sigma0 [m] (one target coordinate)"] == [sigma0]


def test_grid_report_step_per_model_figure_labels_its_x_axis():
    # before: the bars of the step per model pair had ticks "0-2", "2-4" and no axis label
    from photogeom.report.grid_study import _fig_models

    ev = {"steps_before": {(0, 2): 1.5, (2, 4): 1.4}, "steps_after": {(0, 2): 1.1, (2, 4): 1.0}}
    (ax,) = _fig_models(ev).axes
    assert "model pair" in ax.get_xlabel() and ax.get_ylabel() == "step (GSD)"
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["before", "after"]


def test_dlt_report_gives_the_unit_of_the_projection_centre(cli, tmp_path):
    # before: the report's decomposed orientation read "Z0 = 1603.3757; omega" and
    # "Z0 3.4; omega" where the console prints "[m]" after both
    import photogeom as pg

    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    eo = pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10)
    rng = np.random.default_rng(0)
    g = rng.uniform([1050, 750, 100], [1550, 1100, 300], (12, 3))
    xy = pg.project(g, io, eo) + rng.normal(0, 0.003, (12, 2))
    ctl = tmp_path / "c.csv"
    ctl.write_text("id,X,Y,Z,x,y\n" + "".join(
        f"P{i}," + ",".join(map(repr, map(float, [*g[i], *xy[i]]))) + "\n" for i in range(12)
    ))  # fmt: skip
    rep = tmp_path / "dlt.html"
    code, out, err = cli("camera", "dlt", "estimate", ctl, "--report", rep)
    assert code == 0, err
    page = html.unescape(rep.read_text(encoding="utf-8"))
    for line in out.splitlines():
        if line.startswith(("exterior:", "std. dev. (")):
            assert "[m]" in line
    assert re.search(r"Z0 = \S+ \[m\]; omega", page) and re.search(r"Z0 \S+ \[m\]; omega", page)


def test_zero_redundancy_report_does_not_call_its_shown_std_undefined(tmp_path):
    # before: under a table of "0.0063 (a priori)" standard deviations the note read
    # "std. dev. undefined: redundancy 0"
    import photogeom as pg
    from photogeom.report import Report

    src = np.array([[113.016, 0.002], [-112.977, -0.002]])
    dst = np.array([[243.031, 130.007], [17.028, 130.009]])
    fit = pg.estimate_transform("similarity2d", src, dst)
    assert fit.redundancy == 0
    rep = Report("zero redundancy")
    rep.add_fit(fit)
    page = rep.to_html()
    assert "(a priori)" in page and "undefined: redundancy 0" not in page
    assert "std. dev. a priori (from sigma0 a priori; redundancy 0" in page


def test_residual_figure_draws_no_ids_beyond_its_limit():
    # before: every id was written beside its point: a transform estimate of 5000 pairs
    # spent 40 of its 53 s drawing the labels of the report's figure (an unreadable mass)
    from photogeom.report.plots import MAX_ID_LABELS, residual_figure

    rng = np.random.default_rng(2)
    n = MAX_ID_LABELS + 1
    pts, res = rng.uniform(0, 100, (n, 2)), rng.normal(0, 0.01, (n, 2))
    (ax,) = residual_figure(pts, res, [f"P{i}" for i in range(n)], unit="mm").axes
    assert len(ax.texts) == 0 and f"ids not drawn ({n} points" in ax.get_title(loc="left")
    (ax,) = residual_figure(pts[:5], res[:5], [f"P{i}" for i in range(5)], unit="mm").axes
    assert [t.get_text() for t in ax.texts] == [f"P{i}" for i in range(5)]
    assert "ids not drawn" not in ax.get_title(loc="left")


def test_intersection_report_legend_does_not_call_object_points_control(cli, tmp_path):
    # before: the residual plots of 'orient intersection' had the legend "control (12)":
    # the intersected points are neither control nor check points
    import photogeom as pg

    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    eos = [pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10),
           pg.ExteriorOrientation.from_degrees(1600, 820, 1620, -1, 2, 8)]  # fmt: skip
    rng = np.random.default_rng(0)
    g = rng.uniform([1050, 750, 100], [1550, 1100, 300], (6, 3))
    images, cams = [], []
    for k, eo in enumerate(eos):
        xy = pg.project(g, io, eo) + rng.normal(0, 0.003, (6, 2))
        f = tmp_path / f"i{k}.csv"
        rows = [f"P{i},{a!r},{b!r}" for i, (a, b) in enumerate(xy.tolist())]
        f.write_text("id,x,y\n" + "\n".join(rows) + "\n")
        images.append(f)
        cam = tmp_path / f"c{k}.json"
        cam.write_text(json.dumps({"interior": io.to_dict(), "exterior": eo.to_dict("deg")}))
        cams += ["--camera", cam]
    from matplotlib.figure import Figure

    legends = []
    real = Figure.savefig

    def keep(fig, *a, **k):
        legends.extend(t.get_text() for ax in fig.axes if ax.get_legend()
                       for t in ax.get_legend().get_texts())  # fmt: skip
        return real(fig, *a, **k)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Figure, "savefig", keep)
        code, _, err = cli("orient", "intersection", *images, *cams, "--report",
                           tmp_path / "i.html")  # fmt: skip
    assert code == 0, err
    assert legends == ["object points (6)", "object points (6)"]
