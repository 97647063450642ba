"""Honest units and one rule for printed angles: scale parameters in target per source unit,
projective denominators in 1/source, intersection and Helmert units, kappa in [0, one turn)
and other angles in [-half turn, +half turn), PROJ strings without float noise."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.io import write_points
from photogeom.units import display_angle, to_radians

KRAUS = str(pg.datasets.path("kraus_absolute_orientation"))
LIDAR = str(pg.datasets.path("lidar_wang2014"))


def _pixels_to_mm(n=12, seed=0):
    rng = np.random.default_rng(seed)
    px = rng.uniform(0, 4000, (n, 2))
    mm = np.column_stack([0.012 * px[:, 0] - 24, -0.012 * px[:, 1] + 18])
    return px, mm + rng.normal(0, 1e-4, mm.shape)


@pytest.mark.parametrize(
    "model, expected",
    [
        ("similarity2d", {"a": "mm/px", "c": "mm"}),
        ("affine2d", {"a1": "mm/px", "b2": "mm/px", "a3": "mm", "b3": "mm"}),
        ("projective2d", {"a1": "mm/px", "a3": "mm", "c1": "1/px", "c2": "1/px"}),
    ],
)
def test_pixel_to_mm_parameters_carry_mm_per_px(model, expected):
    px, mm = _pixels_to_mm()
    fit = pg.estimate_transform(
        model, px, mm, unit="mm", source_system="pixel", target_system="image"
    )
    for k, v in expected.items():
        assert fit.parameter_units[k] == v, k
    assert all(fit.parameter_units[k] for k in fit.parameter_names)  # none unlabelled


def test_same_units_and_polynomials():
    px, mm = _pixels_to_mm()
    fit = pg.estimate_transform("affine2d", px, mm, unit="mm")  # source assumed in mm too
    assert fit.parameter_units["a1"] == "1"
    fit = pg.estimate_transform("affine2d", px, mm, unit="mm", source_unit="px")
    assert fit.parameter_units["a1"] == "mm/px"
    assert fit.extras["textbook_units"]["sx"] == "mm/px"
    fit = pg.estimate_transform("polynomial2d", px, mm, order=2, unit="mm")
    assert set(fit.parameter_units.values()) == {"mm"}  # coefficients of reduced coordinates


def test_cli_labels_units(cli, tmp_path):
    px, mm = _pixels_to_mm()
    f = tmp_path / "p.csv"
    write_points(f, [str(i) for i in range(len(px))], np.hstack([px, mm]),
                       ["col", "row", "x", "y"])  # fmt: skip
    systems = ("--source-system", "pixel", "--target-system", "image")
    code, out, err = cli("transform", "estimate", "affine2d", f, "--unit", "mm", *systems, "--json")
    assert code == 0, err
    assert json.loads(out)["parameters"]["a1"]["unit"] == "mm/px"


def test_helmert_form_in_text_and_html(cli, tmp_path):
    rep = tmp_path / "r.html"
    code, out, err = cli("transform", "estimate", "similarity3d", LIDAR, "--report", rep)
    assert code == 0, err
    assert "Helmert form (EPSG, position vector convention)" in " ".join(out.split())
    assert re.search(r"\brx\b.*arcsec", out) and re.search(r"\bds\b.*ppm", out)
    html = rep.read_text()
    assert "Helmert form (EPSG, position vector convention)" in html and "ppm" in html


def test_kraus_kappa_is_printed_as_published(cli):
    code, out, err = cli("orient", "absolute", KRAUS, "--angle-unit", "gon")
    assert code == 0, err
    assert re.search(r"kappa\s+298\.6799", out)
    assert "kappa 298.6799" in " ".join(out.split())
    code, out, _ = cli("orient", "absolute", KRAUS, "--angle-unit", "gon", "--json")
    a = json.loads(out)["angles"]
    assert a["kappa"] == pytest.approx(298.6799, abs=1e-4) and a["omega"] < 0
    code, out, _ = cli("orient", "absolute", KRAUS, "--angle-unit", "arcsec")
    assert code == 0 and "arcsec" in out


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-1e4, 1e4, allow_nan=False),
    st.sampled_from(["deg", "gon", "rad", "arcsec"]),
    st.sampled_from(["omega", "phi", "kappa", "theta"]),
)
def test_display_angle_rule(value, unit, name):
    full = {"deg": 360.0, "gon": 400.0, "rad": 2 * np.pi, "arcsec": 1296000.0}[unit]
    out = display_angle(value, unit, name)
    if name == "kappa":
        assert 0.0 <= out < full
    else:
        assert -full / 2 <= out < full / 2
    turns = (value - out) / full  # the same direction
    assert abs(turns - round(turns)) < 1e-9 * max(1.0, abs(value) / full)
    a, b = to_radians(value, unit), to_radians(out, unit)
    assert np.cos(a) == pytest.approx(np.cos(b), abs=1e-9)


def test_proj_string_has_no_float_noise():
    pyproj = pytest.importorskip("pyproj")
    h = pg.Similarity3D.from_helmert(-87.0, -98.0, -121.0, 0.1, -0.247, 0.3, 1.5,
                                     convention="position_vector")  # fmt: skip
    text = h.to_proj_string()
    assert "+ry=-0.247" in text and "+s=1.5" in text
    assert not re.search(r"\d{12,}", text)
    t = pyproj.Transformer.from_pipeline(text)
    x = np.array([4e6, 3e5, 5e6])
    np.testing.assert_allclose(t.transform(*x), h.apply(x), atol=1e-6)


def test_method_comparison_prints_angles_by_the_same_rule(cli):
    code, out, err = cli("orient", "absolute", KRAUS, "--compare", "--angle-unit", "gon")
    assert code == 0, err
    assert "298.6799" in out and "-101.32" not in out
