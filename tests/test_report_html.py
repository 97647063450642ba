"""HTML and console reports of fits: content, numbers, plots, validity, atomic writing."""

from __future__ import annotations

import base64
import os
import re
from html.parser import HTMLParser

import numpy as np
import pytest
from rich.console import Console

from photogeom import datasets
from photogeom.adjust import Fit, solve_linear
from photogeom.errors import InputError
from photogeom.io import read_point_pairs
from photogeom.report import Report, fit_text, nice_length, print_fit, residual_figure
from photogeom.report.format import fmt_std, fmt_value, residual_decimals


def _similarity_fit(src, dst, ids, weights=None, check=None):
    """A 2D similarity fitted with the engine directly (design rows of the lecture)."""
    x, y = src.T
    n = x.size
    A = np.zeros((2 * n, 4))
    A[0::2] = np.column_stack([x, y, np.ones(n), np.zeros(n)])
    A[1::2] = np.column_stack([y, -x, np.zeros(n), np.ones(n)])
    w = None if weights is None else np.repeat(weights, 2)
    adj = solve_linear(A, dst.reshape(-1), weights=w, names=["a", "b", "c", "d"])
    fit = Fit.from_adjustment(
        adj,
        "similarity",
        "linear least squares",
        point_dim=2,
        ids=tuple(ids),
        residual_labels=("X", "Y"),
        residual_unit="mm",
        parameter_units={"a": "1", "b": "1", "c": "mm", "d": "mm"},
    )
    if check is not None:
        a, b, c, d = adj.x
        cs, cd, cids = check
        comp = np.column_stack([a * cs[:, 0] + b * cs[:, 1] + c, -b * cs[:, 0] + a * cs[:, 1] + d])
        fit = fit.with_checks(comp - cd, cids)
    return fit


@pytest.fixture(scope="module")
def fiducial_fit():
    p = read_point_pairs(datasets.path("lecture_fiducials"))
    c, k = ~p.check_mask, p.check_mask
    ids = np.array(p.ids)
    fit = _similarity_fit(
        p.source[c], p.target[c], ids[c], check=(p.source[k], p.target[k], ids[k])
    )
    return fit, p


class _Checker(HTMLParser):
    VOID = frozenset({"meta", "img", "br", "hr", "link", "input"})

    def __init__(self):
        super().__init__()
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.imgs: list[dict] = []

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.imgs.append(dict(attrs))
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"unexpected </{tag}> (open: {self.stack[-3:]})")
        else:
            self.stack.pop()


def _check_html(text: str) -> _Checker:
    chk = _Checker()
    chk.feed(text)
    assert not chk.errors, chk.errors[:3]
    assert chk.stack == [], chk.stack
    assert text.startswith("<!DOCTYPE html>")
    return chk


def test_fit_section_shows_published_numbers(fiducial_fit, tmp_path):
    fit, p = fiducial_fit
    rep = Report("Interior orientation", subtitle="lecture example 4")
    rep.add_text("Data", "Eight fiducial marks.\n\nFour control, four check.")
    rep.add_fit(
        fit, title="Similarity", points=p.target[~p.check_mask], check_points=p.target[p.check_mask]
    )
    out = rep.write(tmp_path / "r.html")
    text = out.read_text()
    chk = _check_html(text)
    # lecture example 4: a = 1.0000354, b = -0.0000022, c = 130.00875, d = 130.009
    for s in ("1.0000354", "-0.0000022", "130.00875", "130.00900"):
        assert f">{s}<" in text
    assert "v = computed - observed" in text and "sigma0 a posteriori" in text
    assert "Check point residuals (4, not in the estimate)" in text
    # published residuals of control point 1 and check point 7 (mm)
    assert ">-0.00225<" in text and ">0.00425<" in text and ">-0.00850<" in text
    assert "RMSE per point" in text and "redundancy r" in text
    # exactly one embedded PNG, decodable
    assert len(chk.imgs) == 1
    src = chk.imgs[0]["src"]
    assert src.startswith("data:image/png;base64,")
    assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    assert "http" not in re.sub(r"https?://[^\s\"]*w3\.org[^\s\"]*", "", text)  # self-contained


def test_redundancy_zero_does_not_crash(tmp_path):
    src = np.array([[0.0, 0.0], [10.0, 0.0]])
    dst = np.array([[1.0, 2.0], [11.0, 2.5]])
    fit = _similarity_fit(src, dst, ["A", "B"])
    assert fit.redundancy == 0 and np.isnan(fit.sigma0)
    console = Console(record=True, width=120, color_system=None)
    print_fit(fit, console=console)
    out = console.export_text()
    assert "undefined (redundancy 0)" in out
    rep = Report("r = 0")
    rep.add_fit(fit, points=src)
    text = rep.to_html()
    _check_html(text)
    assert "undefined" in text


def test_print_fit_units_and_angles(fiducial_fit):
    fit, _ = fiducial_fit
    console = Console(record=True, width=120, color_system=None)
    print_fit(fit, console=console)
    out = console.export_text()
    assert "1.0000354" in out and "130.00875" in out and " mm" in out
    assert "v = computed - observed [mm]" in out
    assert "Check point residuals (4, not in the estimate)" in out
    assert fit_text(fit).count("1.0000354") == 1


def test_outlier_is_flagged():
    rng = np.random.default_rng(7)
    src = rng.uniform(-100, 100, (12, 2))
    true = np.column_stack(
        [src[:, 0] * 0.9 + 0.1 * src[:, 1] + 5, -0.1 * src[:, 0] + 0.9 * src[:, 1]]
    )
    dst = true + rng.normal(0, 0.01, true.shape)
    dst[3, 0] += 0.3  # gross error of 30 sigma
    fit = _similarity_fit(src, dst, [f"P{k}" for k in range(12)], weights=np.full(12, 1e4))
    rep = Report("outlier")
    rep.add_fit(fit)
    text = rep.to_html()
    flagged = re.findall(r'<td class="flag">([^<]*)</td>', text)
    assert flagged, "the 30-sigma error must be flagged"
    row = re.search(r"<tr><td>P3</td>(.*?)</tr>", text).group(1)
    assert 'class="flag"' in row
    assert "w-test (Baarda" in text and "critical value 3.291" in text


def test_tables_text_and_toc():
    rep = Report("Many sections")
    rep.add_heading("Chapter", "Intro text.")
    rep.add_table("Numbers", ["name", "value"], [["pi", np.pi], ["n", 3], ["none", float("nan")]])
    rep.add_text("Aligned", "a    1\nbb   2")
    rep.add_text("Para", "plain <b> text & more")
    rep.add_text(None, "no heading")
    text = rep.to_html()
    _check_html(text)
    assert "<nav>" in text and 'href="#chapter"' in text
    assert ">3.141592654<" in text and "<pre>a    1" in text
    assert "plain &lt;b&gt; text &amp; more" in text  # escaped
    assert rep.headings[:2] == ["Chapter", "Numbers"]


def test_add_figure_embeds_png():
    from matplotlib.figure import Figure

    fig = Figure()
    fig.add_subplot(1, 1, 1).plot([0, 1], [1, 0])
    rep = Report("fig")
    rep.add_figure("A line", fig, caption="caption text")
    chk = _check_html(rep.to_html())
    assert len(chk.imgs) == 1 and "caption text" in rep.to_html()


def test_residual_plot_scale_arrow_and_ids():
    pts = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]])
    res = np.array([[0.003, 0.0], [0.0, -0.004], [0.001, 0.001]])
    fig = residual_figure(pts, res, ["a", "b", "c"], unit="mm", labels=("col", "row"), y_down=True)
    ax = fig.axes[0]
    texts = [t.get_text() for t in ax.texts]
    assert {"a", "b", "c"} <= set(texts)
    from matplotlib.quiver import QuiverKey

    keys = [c for c in ax.get_children() if isinstance(c, QuiverKey)]
    assert len(keys) == 1 and keys[0].text.get_text() == "0.002 mm" and keys[0].U == 0.002
    assert ax.get_ylim()[0] > ax.get_ylim()[1]  # row axis drawn downwards
    assert "computed - observed" in ax.get_title(loc="left")
    with pytest.raises(InputError, match="3 point"):
        residual_figure(pts, res[:2])
    zero = residual_figure(pts, np.zeros_like(res))
    assert "all residuals are zero" in zero.axes[0].get_title(loc="left")
    rep = Report("plot")
    rep.add_residual_plot("vectors", pts, res, ids=["a", "b", "c"], unit="mm")
    assert len(_check_html(rep.to_html()).imgs) == 1


@pytest.mark.parametrize(
    "value, expected",
    [(0.0047, 0.002), (0.01, 0.01), (7.0, 5.0), (1.99e-6, 1e-6), (250.0, 200.0)],
)
def test_nice_length(value, expected):
    assert nice_length(value) == pytest.approx(expected)


def test_number_formatting():
    assert fmt_value(1.00003540123, 1.66e-5) == "1.0000354"
    assert fmt_value(130.0087499, 0.0019) == "130.00875"
    assert fmt_value(2.5, float("nan")) == "2.5"
    assert fmt_std(float("nan")) == "-" and fmt_std(0.0019) == "0.0019"
    assert residual_decimals(np.array([0.00225, -0.0045])) == 5


def test_report_write_is_atomic(tmp_path, monkeypatch):
    target = tmp_path / "r.html"
    target.write_text("previous report")

    def failing_replace(src, dst):
        raise OSError("simulated crash")

    monkeypatch.setattr(os, "replace", failing_replace)
    rep = Report("x")
    rep.add_text("t", "text")
    with pytest.raises(OSError, match="simulated crash"):
        rep.write(target)
    assert target.read_text() == "previous report"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.html"]
