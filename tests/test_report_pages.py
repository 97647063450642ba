"""What a reader of the HTML reports meets: wide tables scroll in their box, the method
comparison fits the page, ids the plot font cannot draw are numbered (no empty boxes, no
warnings), the scale arrow sits apart from the title, absolute orientation plots check points."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

import photogeom as pg
from photogeom.io import write_points
from photogeom.report import Report, residual_figure
from photogeom.report.plots import point_labels

LIDAR = str(pg.datasets.path("lidar_wang2014"))


def test_tables_scroll_inside_their_box():
    rep = Report("t")
    rep.add_table("wide", [f"c{i}" for i in range(30)], [[1.0] * 30])
    html = rep.to_html()
    assert '<div class="tbl"><table>' in html and "div.tbl{max-width:100%;overflow-x:auto}" in html


def test_method_comparison_is_two_tables_of_at_most_eight_columns(cli, tmp_path):
    out = tmp_path / "cmp.html"
    code, _, err = cli("orient", "absolute", LIDAR, "--compare", "--report", out)
    assert code == 0, err
    html = out.read_text()
    tables = re.findall(r"<table>(.*?)</table>", html, flags=re.S)
    heads = [t.split("</tr>")[0].count("<th>") for t in tables]
    assert len(heads) == 2 and max(heads) <= 8
    assert "differences to the converged gauss-markov solution, speed" in html


def test_ids_the_font_cannot_draw_are_numbered_without_warnings():
    labels, font, missing = point_labels(["A1", "東京", "Zürich"])
    if font is None:  # no installed font draws CJK (the usual case on servers)
        assert labels == ["A1", "#2", "Zürich"] and missing == ["#2 = 東京"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a missing glyph is a UserWarning
        fig = residual_figure(
            np.array([[0.0, 0], [1, 0], [0, 1]]),
            np.array([[0.01, 0], [0, 0.01], [0.01, 0.01]]),
            ["A1", "東京", "Zürich"],
            unit="mm",
        )
        rep = Report("ids")
        rep.add_figure("f", fig)
        rep.to_html()
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert "Zürich" in texts


def test_scale_arrow_is_inside_the_axes_below_the_title():
    pts = np.array([[0.0, 0], [10, 0], [0, 10]])
    title = "a long title that reaches across the whole figure"
    fig = residual_figure(pts, np.ones((3, 2)) * 0.01, unit="m", title=title)
    fig.canvas.draw()
    ax = fig.axes[0]
    keys = [a for a in ax.artists if type(a).__name__ == "QuiverKey"]
    assert keys and 0 < keys[0].X < 0.5 and 0 < keys[0].Y < 0.5
    title = ax.title.get_window_extent()
    assert keys[0].text.get_window_extent().y1 < title.y0


def test_absolute_orientation_report_plots_check_points(cli, tmp_path, monkeypatch):
    import photogeom.report.html as html_mod

    seen = {}
    original = html_mod.residual_figure

    def spy(*args, **kwargs):
        seen.update(kwargs)
        return original(*args, **kwargs)

    monkeypatch.setattr(html_mod, "residual_figure", spy)
    rng = np.random.default_rng(1)
    x = rng.uniform(-10, 10, (12, 3))
    X = 2 * x + 1 + rng.normal(0, 1e-3, x.shape)
    f = tmp_path / "p.csv"
    roles = ["control"] * 9 + ["check"] * 3
    write_points(f, [f"p{i}" for i in range(12)], np.hstack([x, X]),
                 ["x", "y", "z", "X", "Y", "Z"], extra={"role": roles})  # fmt: skip
    code, _, err = cli("orient", "absolute", f, "--report", tmp_path / "r.html")
    assert code == 0, err
    assert seen.get("check_points") is not None and len(seen["check_points"]) == 3
    assert list(seen["check_ids"]) == ["p9", "p10", "p11"]


@pytest.mark.parametrize("y_down", [False, True])
def test_check_points_get_their_own_colour_and_legend(y_down):
    pts = np.array([[0.0, 0], [1, 0], [0, 1]])
    check = {"check_points": np.array([[1.0, 1]]), "check_residuals": np.array([[0.0, 0.01]])}
    fig = residual_figure(pts, np.ones((3, 2)) * 0.01, check_ids=["c1"], y_down=y_down, **check)
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert legend == ["control (3)", "check (1)"]
