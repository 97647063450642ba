"""Strict number reading: one rule for CSV columns, Metashape XML and RPC text.

Python's float() reads "3_500.5" and non-ASCII digits; no file means those, and the CSV
reader refused them while the Metashape and RPC readers took them.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

import photogeom as pg
from photogeom.errors import FileFormatError
from photogeom.io import read_points
from photogeom.numbers import is_decimal_number, parse_decimal
from photogeom.rpc import RPC

REFUSED = ["3_500.5", "1_0", "\u0663", "1\u0660", "\uff11.5", "", "abc", "1.2.3", "0x10", "1e"]
ACCEPTED = {"-12": -12.0, ".5": 0.5, "1e-3": 1e-3, "+1.2E+03": 1200.0, " 7 ": 7.0, "5.": 5.0}


@given(st.floats(allow_nan=False))
def test_every_float_written_by_python_reads_back_exactly(x):
    for text in (repr(x), f"{x:.17e}", f"{x:.17g}"):
        assert is_decimal_number(text)
        assert parse_decimal(text) == x


@given(st.integers(min_value=10, max_value=10**12), st.data())
def test_digit_grouping_is_refused_anywhere(n, data):
    digits = str(n)
    k = data.draw(st.integers(min_value=1, max_value=len(digits) - 1))
    text = digits[:k] + "_" + digits[k:]
    assert float(text) == n  # what Python's float() would have read
    assert not is_decimal_number(text)
    with pytest.raises(ValueError):
        parse_decimal(text)


@pytest.mark.parametrize("text", REFUSED)
def test_refused_forms(text):
    assert not is_decimal_number(text)
    with pytest.raises(ValueError):
        parse_decimal(text)


@pytest.mark.parametrize("text, value", ACCEPTED.items())
def test_accepted_forms(text, value):
    assert parse_decimal(text) == value


def test_inf_and_nan_are_returned_for_the_reader_to_judge():
    assert parse_decimal("inf") == math.inf and parse_decimal("-Infinity") == -math.inf
    assert math.isnan(parse_decimal("nan"))


@pytest.mark.parametrize("text", [*REFUSED[:5], *ACCEPTED])
def test_the_csv_reader_follows_the_same_rule(tmp_path, text):
    p = tmp_path / "p.csv"
    p.write_text(f"id,x,y\na,{text.strip() or ''},1\n", encoding="utf-8")
    if is_decimal_number(text):
        assert read_points(p, ["x", "y"]).coords[0, 0] == parse_decimal(text)
    else:
        with pytest.raises(FileFormatError, match="not a number"):
            read_points(p, ["x", "y"])


METASHAPE = """<?xml version="1.0" encoding="UTF-8"?>
<calibration>
  <projection>frame</projection>
  <width>{width}</width>
  <height>4000</height>
  <f>{f}</f>
  <cx>12.3</cx>
</calibration>
"""


@pytest.mark.parametrize(
    "width, f, tag, shown",
    [
        ("6000", "3_500.5", "f", "'3_500.5'"),
        ("6_000", "3500.5", "width", "'6_000'"),
        ("6000", "\u0663500", "f", "'\u0663500'"),
    ],
)
def test_metashape_xml_refuses_underscores_and_non_ascii_digits(tmp_path, width, f, tag, shown):
    path = tmp_path / "cal.xml"
    path.write_text(METASHAPE.format(width=width, f=f), encoding="utf-8")
    with pytest.raises(FileFormatError) as err:
        pg.camera.read_metashape_xml(path)
    msg = str(err.value)
    assert str(path) in msg and f"<{tag}>" in msg and shown in msg and "'_'" in msg


def test_metashape_xml_still_reads_plain_numbers(tmp_path):
    path = tmp_path / "cal.xml"
    path.write_text(METASHAPE.format(width="6000", f="3.5005E+03"), encoding="utf-8")
    c = pg.camera.read_metashape_xml(path)
    assert (c.width, c.f, c.cx) == (6000, 3500.5, 12.3)


@pytest.mark.parametrize(
    "old, new, key, shown",
    [
        ("LINE_OFF: +005124.00", "LINE_OFF: +005_124.00", "LINE_OFF", "'+005_124.00'"),
        (
            "LINE_NUM_COEFF_2: +1.2",
            "LINE_NUM_COEFF_2: +\u0661.2",
            "LINE_NUM_COEFF_2",
            "'+\u0661.221942364020734E+00'",
        ),
    ],
)
def test_rpc_text_refuses_underscores_and_non_ascii_digits(tmp_path, old, new, key, shown):
    text = pg.datasets.path("ikonos").read_text()
    assert old in text
    path = tmp_path / "rpc.txt"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(FileFormatError) as err:
        RPC.from_file(path)
    msg = str(err.value)
    assert str(path) in msg and key in msg and shown in msg and "'_'" in msg


def test_rpc_text_unchanged_for_plain_numbers(tmp_path):
    path = tmp_path / "rpc.txt"
    path.write_text(pg.datasets.path("ikonos").read_text(), encoding="utf-8")
    assert RPC.from_file(path).line_off == 5124.0
