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
