"""Run times in the text and HTML reports: three significant digits, never an exponent."""

from __future__ import annotations

import dataclasses
import re
import sys
from pathlib import Path

import pytest

import photogeom as pg
from photogeom.report import Report, fit_text
from photogeom.report.bundle import _summary_rows, bundle_result_data
from photogeom.report.format import fmt_duration

sys.path.insert(0, str(Path(__file__).parent))
from html_tables import table_rows


@pytest.mark.parametrize(
    ("seconds", "text"),
    [
        (0.0146, "14.6 ms"),
        (0.00042, "0.420 ms"),
        (0.9997, "1.00 s"),  # not "1000 ms"
        (2.85, "2.85 s"),  # was "2.85e+03 ms"
        (9.997, "10.0 s"),
        (104.47, "104 s"),
        (1500.0, "1500 s"),
        (float("nan"), "-"),
    ],
)
def test_fmt_duration(seconds, text):
    assert fmt_duration(seconds) == text


@pytest.fixture(scope="module")
def fiducial_fit():
    p = pg.io.read_point_pairs(pg.datasets.path("lecture_fiducials"))
    return pg.estimate_transform(
        "similarity2d", p.source, p.target, check=p.check_mask, ids=p.ids, unit="mm"
    )


@pytest.mark.parametrize(("elapsed", "shown"), [(2.85, "2.85 s"), (0.0146, "14.6 ms")])
def test_fit_report_and_text_give_the_time_without_exponent(fiducial_fit, elapsed, shown):
    # a relative orientation of 400 points took 2.85 s and both reports said "2.85e+03 ms"
    fit = dataclasses.replace(fiducial_fit, elapsed=elapsed)
    rep = Report("t")
    rep.add_fit(fit)
    assert table_rows(rep.to_html())["time"] == [shown]
    assert re.search(rf"time\s+{re.escape(shown)}", fit_text(fit))


def test_bundle_report_time_has_the_digits_of_the_printed_summary():
    sim = pg.simulate.uav_block(
        "FC300S", seed=2, strips=1, images_per_strip=3, tie_points_per_image=40, local_field=0.0
    )
    fit = dataclasses.replace(pg.bundle_adjust(sim.block, snooping=False), elapsed=1534.567)
    printed = re.search(r"iteration\(s\), (\S+ s)", fit.summary()).group(1)
    assert printed == "1534.57 s"
    # the summary table of the report (bundle_report renders these rows; its figures are
    # left out to keep the test fast)
    rows = dict(_summary_rows(bundle_result_data(fit)))
    assert rows["time"] == printed  # was "1.53e+03 s"
