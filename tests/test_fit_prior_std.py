"""A-priori standard deviations where the a-posteriori ones are undefined (redundancy 0)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg
from photogeom.report.format import fmt_std, parameter_rows


def _pairs(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    src = rng.uniform(0, 100, (n, 2))
    c, s = 1.01 * np.cos(0.3), 1.01 * np.sin(0.3)
    dst = src @ np.array([[c, -s], [s, c]]).T + [10.0, -4.0] + rng.normal(0, 0.02, (n, 2))
    return src, dst


def _parameter_lines(fit) -> list[str]:
    names = tuple(f"  {n} " for n in fit.parameter_names)
    return [line for line in fit.summary().splitlines() if line.startswith(names)]


def test_redundancy_zero_shows_the_a_priori_std():
    src, dst = _pairs(2)  # a 2D similarity from two points: redundancy 0
    fit = pg.estimate_transform("similarity2d", src, dst, sigma0_prior=0.02)
    assert fit.redundancy == 0 and not np.isfinite(fit.sigma0)
    d = fit.to_dict()
    for name, entry in d["parameters"].items():
        assert entry["std"] is None or not np.isfinite(entry["std"])
        # sigma0_prior times the square root of the cofactor's diagonal
        q = fit.cofactor[fit.parameter_names.index(name), fit.parameter_names.index(name)]
        assert entry["std_prior"] == pytest.approx(0.02 * np.sqrt(q), rel=1e-12)
    assert json.loads(json.dumps(d))["parameters"]  # serialisable
    rows = parameter_rows(fit)
    assert all(r[2].endswith("(a priori)") for r in rows)
    lines = _parameter_lines(fit)
    assert len(lines) == 4 and all("(a priori)" in line for line in lines)


def test_with_redundancy_the_a_posteriori_std_is_shown():
    src, dst = _pairs(8)
    fit = pg.estimate_transform("similarity2d", src, dst, sigma0_prior=0.02)
    d = fit.to_dict()
    for entry in d["parameters"].values():
        # a posteriori = a priori scaled by sigma0 / sigma0_prior
        assert entry["std"] == pytest.approx(entry["std_prior"] * fit.sigma0 / 0.02, rel=1e-9)
    assert not any("(a priori)" in r[2] for r in parameter_rows(fit))
    assert not any("(a priori)" in line for line in _parameter_lines(fit))


@pytest.mark.parametrize(
    ("s", "text"),
    [
        (204.0, "200"),
        (1234.0, "1200"),
        (0.35, "0.35"),
        (1.05, "1.1"),
        (12.3, "12"),
        (2e-5, "2.00e-05"),
    ],
)
def test_standard_deviations_print_without_needless_exponents(s, text):
    assert fmt_std(s) == text
