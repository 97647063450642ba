"""Residual tables of HTML reports of fits with many points: the worst rows, and a note."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.report import Report
from photogeom.report.html import MAX_RESIDUAL_ROWS

sys.path.insert(0, str(Path(__file__).parent))
from html_tables import table_rows


def _section(text: str, heading: str) -> str:
    """The HTML from the ``<h4>`` starting with ``heading`` to the next ``<h4>`` or figure."""
    start = text.index(f"<h4>{heading}")
    end = re.search(r"<h4>|<figure>|</section>", text[start + 4 :])
    return text[start : start + 4 + (end.start() if end else len(text))]


@pytest.fixture(scope="module")
def many_points():
    """An affine 2D fit of 1500 control points (noise 0.01 m) with blunders of 0.5-0.9 m at
    five points, and 400 check points with a 0.3 m error at one of them."""
    rng = np.random.default_rng(7)
    n = 1900
    src = rng.uniform(0, 1000, (n, 2))
    dst = src @ np.array([[1.0001, 0.0002], [-0.0002, 1.0001]]) + [100.0, 200.0]
    dst += rng.normal(0, 0.01, (n, 2))
    blunders = {"p17": 0.9, "p400": 0.8, "p901": 0.7, "p1203": 0.6, "p1499": 0.5}
    for pid, size in blunders.items():
        dst[int(pid[1:]), 0] += size
    dst[1600, 1] += 0.3
    check = np.arange(n) >= 1500
    ids = [f"p{k}" for k in range(n)]
    fit = pg.estimate_transform(
        "affine2d", src, dst, check=check, ids=ids, unit="m", sigma0_prior=0.01
    )
    rep = Report("many points")
    rep.add_fit(fit)
    return fit, rep.to_html(), blunders


def test_control_table_shows_the_worst_rows_first(many_points):
    fit, text, blunders = many_points
    part = _section(text, "Control point residuals")
    assert part.startswith("<h4>Control point residuals (1500)</h4>")  # all points counted
    rows = table_rows(part)
    del rows["id"]
    assert len(rows) == MAX_RESIDUAL_ROWS == 100
    # the planted blunders lead, largest first (their w-test statistics follow their sizes)
    assert list(rows)[:5] == list(blunders)
    assert "the 100 of 1500 control points with the largest |w| (largest first)" in part
    # a row kept has |w| at least that of any row left out (the 100th largest of 1500)
    w = np.abs(np.asarray(fit.snooping(sigma="prior").statistic).reshape(-1, 2)).max(axis=1)
    shown = [fit.ids.index(pid) for pid in rows]
    assert w[shown].min() >= np.sort(w)[-100] - 1e-12


def test_check_table_shows_the_largest_residuals_first(many_points):
    _, text, _ = many_points
    part = _section(text, "Check point residuals")
    assert part.startswith("<h4>Check point residuals (400, not in the estimate)</h4>")
    rows = table_rows(part)
    del rows["id"]
    assert len(rows) == 100
    assert next(iter(rows)) == "p1600"
    assert "the 100 of 400 check points with the largest |v|" in part


def test_report_size_stays_small(many_points):
    _, text, _ = many_points
    # every row: 216 kB; the 200 rows shown and the statistics: 25 kB
    assert len(text) < 40_000, len(text)


def test_a_small_fit_keeps_every_row_in_its_order():
    p = pg.io.read_point_pairs(pg.datasets.path("lecture_fiducials"))
    fit = pg.estimate_transform(
        "similarity2d", p.source, p.target, check=p.check_mask, ids=p.ids, unit="mm"
    )
    rep = Report("fiducials")
    rep.add_fit(fit)
    text = rep.to_html()
    rows = table_rows(_section(text, "Control point residuals"))
    assert list(rows)[1:] == ["1", "2", "3", "4"]
    assert "largest" not in _section(text, "Control point residuals")
