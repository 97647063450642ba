"""``--unit`` of ``transform estimate`` and ``orient absolute``.

Before: ``transform estimate similarity3d --unit mm`` printed its shifts in mm but the same
shifts in the Helmert form (text, report and ``--json`` ``extras.helmert.units``) in ``m``;
without ``--unit`` similarity3d and rigid3d labelled everything ``m`` while affine3d and the
2D models (the same command, the same option) labelled nothing.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg


@pytest.fixture(scope="module")
def pairs(tmp_path_factory):
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 100, (8, 3))
    y = 1.001 * x @ pg.opk_matrix(0.01, 0.02, 0.3).T + [10, 20, 30] + rng.normal(0, 0.01, (8, 3))
    p = tmp_path_factory.mktemp("u") / "pts.csv"
    p.write_text("id,x,y,z,X,Y,Z\n" + "".join(
        f"{i}," + ",".join(repr(float(v)) for v in (*a, *b)) + "\n"
        for i, (a, b) in enumerate(zip(x, y))))  # fmt: skip
    return p, x, y


def test_helmert_shifts_carry_the_unit(pairs, cli):
    path, x, y = pairs
    fit = pg.estimate_transform("similarity3d", x, y, unit="mm")
    assert fit.extras["helmert"]["units"]["tx"] == "mm"
    code, out, _ = cli("transform", "estimate", "similarity3d", path, "--unit", "mm", "--json")
    assert code == 0
    d = json.loads(out)
    assert d["extras"]["helmert"]["units"]["tz"] == "mm" and d["residual_unit"] == "mm"
    code, out, _ = cli("transform", "estimate", "similarity3d", path, "--unit", "mm")
    helmert = out[out.index("Helmert form"):out.index("Adjustment")]
    assert [ln.split()[-1] for ln in helmert.splitlines() if ln.split()[:1] == ["tx"]] == ["mm"]


@pytest.mark.parametrize("model", ["similarity3d", "rigid3d", "affine3d"])
def test_no_unit_no_length_label_for_every_3d_model(pairs, model):
    _, x, y = pairs
    fit = pg.estimate_transform(model, x, y)
    assert fit.residual_unit == "" and fit.parameter_units["tx"] == ""


def test_orient_absolute_and_transform_estimate_label_alike(pairs, cli):
    path = pairs[0]
    _, a, _ = cli("orient", "absolute", path, "--unit", "ft", "--json")
    _, t, _ = cli("transform", "estimate", "similarity3d", path, "--unit", "ft", "--json")
    a, t = json.loads(a), json.loads(t)
    assert a["residual_unit"] == t["residual_unit"] == "ft"
    assert {k: v["unit"] for k, v in a["parameters"].items()} == {
        k: v["unit"] for k, v in t["parameters"].items()
    }


def test_help_words_the_option_alike(cli):
    texts = [cli(*c, "--help")[1] for c in (("orient", "absolute"),
                                            ("transform", "estimate"))]  # fmt: skip
    for text in texts:
        flat = " ".join(text.split())
        assert "Length unit of the target coordinates, labelling shifts, residuals and RMS" in flat
