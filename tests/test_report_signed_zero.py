"""Values that round to zero are shown without a minus sign in the parameter tables."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.report import Report, fit_text
from photogeom.report.format import fmt_value

sys.path.insert(0, str(Path(__file__).parent))
from html_tables import table_rows


def _near_zero_rotation():
    """A 2D similarity of four points on a centred cross of radius 100 m whose rotation
    parameter b is -4e-9 with a standard deviation of 2.5e-5: with centred source points
    b = sum(y X - x Y) / sum(x^2 + y^2), so an X offset of -1.6e-6 m at (0, 100) gives
    b = -1.6e-4 / 4e4; Y offsets of 0.01 m at (0, +-100) leave a and b alone and give
    residuals of 5 mm (sigma0 0.005, std of b 0.005 / 200)."""
    src = np.array([[100.0, 0.0], [0.0, 100.0], [-100.0, 0.0], [0.0, -100.0]])
    dst = src + np.array([500.0, 600.0])
    dst[1, 0] -= 1.6e-6
    dst[[1, 3], 1] += 0.01
    return pg.estimate_transform("similarity2d", src, dst, unit="m")


def test_parameter_table_shows_no_negative_zero():
    fit = _near_zero_rotation()
    assert fit.params["b"] == pytest.approx(-4e-9, rel=1e-3)
    assert fit.std_errors["b"] == pytest.approx(2.5e-5, rel=1e-3)
    rep = Report("t")
    rep.add_fit(fit)
    assert table_rows(rep.to_html())["b"] == ["0.0000000", "2.50e-05", "1"]  # was "-0.0000000"
    assert "-0.0000000" not in fit_text(fit)


@pytest.mark.parametrize(
    ("value", "std", "text"),
    [
        (-0.00004, 0.015, "0.0000"),  # an angle of a bundle report's exterior table
        (-0.0, None, "0"),  # a held value read as -0
        (-0.5, 0.01, "-0.5000"),
        (-1e-12, None, "-1e-12"),
        (-1234.5, 100.0, "-1234"),
    ],
)
def test_fmt_value_sign(value, std, text):
    assert fmt_value(value, std) == text


@pytest.mark.parametrize(
    ("value", "std", "text"),
    [
        # exact data: the std is rounding noise, a value within it is zero (was
        # "9.900075136e-17", ten digits of noise)
        (9.900075136e-17, 9.99e-17, "0"),
        (-6.720573213e-17, 3e-14, "0"),
        # a tiny value known beyond its std keeps the digits its std gives, not ten
        (-6.720573213e-17, 1e-17, "-6.72e-17"),
        (1.23456789e-20, 4e-22, "1.2346e-20"),
        # values of ordinary size with a tiny std: at most ten significant digits
        (100.00000000000001, 9.31e-15, "100"),
        (1.0000000000000002, 9.99e-17, "1"),
        (1234.56789012345678, 1e-14, "1234.56789"),
    ],
)
def test_fmt_value_with_a_std_below_1e_13(value, std, text):
    assert fmt_value(value, std) == text


def test_exact_similarity_parameter_table():
    """Exact data: the rotation parameter b is rounding noise and shown as 0, a and the
    shifts without spurious digits."""
    src = np.array([[0.0, 0.0], [100, 0], [0, 100], [100, 100], [50, 30]])
    fit = pg.estimate_transform("similarity2d", src, src + np.array([100.0, 200.0]))
    assert fit.std_errors["b"] < 1e-13 and abs(fit.params["b"]) <= fit.std_errors["b"]
    rep = Report("t")
    rep.add_fit(fit)
    rows = table_rows(rep.to_html())
    assert rows["b"][0] == "0" and rows["a"][0] == "1" and rows["c"][0] == "100"
