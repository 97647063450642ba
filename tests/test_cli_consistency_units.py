"""`photogeom transform apply` records the unit of its output coordinates.

``transform estimate --unit mm --source-unit px --output-params p.json`` labels everything in
mm and mm/px, but ``transform apply p.json pts.csv`` wrote coordinates with no unit at all
(the ``# crs:`` line is written only with a CRS). The estimate now records both units in its
``input`` section, and apply writes a ``# unit:`` line (the source unit with ``--inverse``);
``--unit`` names it when the file records none and is refused when it contradicts the record.
"""

from __future__ import annotations

import json

import numpy as np

from photogeom import datasets
from photogeom.io import read_points

FID = datasets.path("lecture_fiducials")
KRAUS = datasets.path("kraus_absolute_orientation")


def _comments(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("#")]


def test_apply_writes_the_unit_of_each_side(cli, tmp_path):
    params = tmp_path / "p.json"
    code, _, err = cli("transform", "estimate", "similarity2d", FID, "--unit", "mm",
                       "--source-unit", "px", "--output-params", params)  # fmt: skip
    assert code == 0, err
    record = json.loads(params.read_text())["input"]
    assert record["unit"] == "mm" and record["source_unit"] == "px"
    out = tmp_path / "out.csv"
    code, _, err = cli("transform", "apply", params, FID, "-o", out)
    assert code == 0, err
    assert "# unit: mm" in _comments(out.read_text())
    assert len(read_points(out).ids) == 8  # the line is a comment to the readers
    code, text, err = cli("transform", "apply", params, FID, "--inverse")
    assert code == 0, err
    assert "# unit: px" in _comments(text)


def test_apply_unit_option(cli, tmp_path):
    params = tmp_path / "p.json"
    code, _, err = cli("transform", "estimate", "similarity2d", FID, "--unit", "mm",
                       "--output-params", params)  # fmt: skip
    assert code == 0, err
    code, _, err = cli("transform", "apply", params, FID, "--unit", "m")
    assert code == 2
    assert "--unit m" in err and "records the target unit mm" in err
    code, text, err = cli("transform", "apply", params, FID, "--unit", "mm")
    assert code == 0, err
    assert "# unit: mm" in _comments(text)
    # a bare model dictionary records no unit: --unit names it
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(json.loads(params.read_text())["model_parameters"]))
    code, text, err = cli("transform", "apply", bare, FID)
    assert code == 0, err
    assert not any(c.startswith("# unit:") for c in _comments(text))
    code, text, err = cli("transform", "apply", bare, FID, "--unit", "ft")
    assert code == 0, err
    assert "# unit: ft" in _comments(text)
    code, _, err = cli("transform", "apply", bare, FID, "--unit", "m\ncrs: EPSG:4326")
    assert code == 2 and "on one line" in err


def test_orient_absolute_records_its_unit(cli, tmp_path):
    params = tmp_path / "a.json"
    code, _, err = cli("orient", "absolute", KRAUS, "--output-params", params)
    assert code == 0, err
    assert json.loads(params.read_text())["input"]["unit"] == "m"
    code, text, err = cli("transform", "apply", params, KRAUS)
    assert code == 0, err
    assert "# unit: m" in _comments(text)
    # the model side records no unit: --inverse writes none unless --unit names it
    code, text, err = cli("transform", "apply", params, KRAUS, "--inverse")
    assert code == 0, err
    assert not any(c.startswith("# unit:") for c in _comments(text))
    assert np.isfinite(float(text.splitlines()[-1].split(",")[1]))
