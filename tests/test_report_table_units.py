"""Residual tables of the text and HTML reports give the unit in their headings."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

import photogeom as pg
from photogeom.report import Report, fit_text

sys.path.insert(0, str(Path(__file__).parent))
from html_tables import table_rows


def _fit(unit):
    p = pg.io.read_point_pairs(pg.datasets.path("lecture_fiducials"))
    return pg.estimate_transform(
        "similarity2d", p.source, p.target, check=p.check_mask, ids=p.ids, unit=unit
    )


def _headings(text: str) -> list[list[str]]:
    """The heading rows (first cell 'id') of the tables of an HTML report, in order."""
    out = []
    for row in re.findall(r"<tr>(<th>.*?)</tr>", text):
        cells = re.findall(r"<th>(.*?)</th>", row)
        if cells[0] == "id":
            out.append(cells)
    return out


def test_html_residual_headings_carry_the_unit():
    # before: "v_x", "v_y", "|v|", the unit only in a note under the table
    rep = Report("t")
    rep.add_fit(_fit("mm"))
    control, check = _headings(rep.to_html())
    assert control == [
        "id", "v_x [mm]", "v_y [mm]", "|v| [mm]", "w_x", "w_y", "tau_x", "tau_y",
    ]  # fmt: skip
    assert check == ["id", "v_x [mm]", "v_y [mm]", "|v| [mm]"]
    # the numbers under them are unchanged (the lecture's residuals of mark 1, mm)
    assert table_rows(rep.to_html())["1"][:3] == ["-0.00225", "0.00425", "0.00481"]


def test_text_residual_headings_carry_the_unit():
    text = fit_text(_fit("mm"))
    assert re.search(r"id\s+v_x \[mm\]\s+v_y \[mm\]\s+\|v\| \[mm\]\s+w_x", text)


@pytest.mark.parametrize("unit", [None, ""])
def test_no_unit_no_brackets(unit):
    rep = Report("t")
    rep.add_fit(_fit(unit))
    assert _headings(rep.to_html())[0][:4] == ["id", "v_x", "v_y", "|v|"]
