"""The object-point table of the 'orient intersection' report names the ground unit."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import photogeom as pg


@pytest.fixture
def pair(tmp_path):
    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    eos = [pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10),
           pg.ExteriorOrientation.from_degrees(1600, 820, 1620, -1, 2, 8)]  # fmt: skip
    rng = np.random.default_rng(0)
    g = rng.uniform([1050, 750, 100], [1550, 1100, 300], (6, 3))
    args = []
    for k, eo in enumerate(eos):
        xy = pg.project(g, io, eo) + rng.normal(0, 0.003, (6, 2))
        f = tmp_path / f"i{k}.csv"
        rows = "".join(f"P{i},{a!r},{b!r}\n" for i, (a, b) in enumerate(xy.tolist()))
        f.write_text("id,x,y\n" + rows)
        cam = tmp_path / f"c{k}.json"
        cam.write_text(json.dumps({"interior": io.to_dict(), "exterior": eo.to_dict("deg")}))
        args += [f]
    return args + [a for k in range(2) for a in ("--camera", tmp_path / f"c{k}.json")]


def _heading(path) -> list[str]:
    text = path.read_text(encoding="utf-8")
    row = re.search(r"<tr>(<th>id</th>.*?)</tr>", text).group(1)
    return re.findall(r"<th>(.*?)</th>", row)


def test_headings_carry_the_unit_of_the_ground_crs(cli, pair, tmp_path):
    # before: 'X', 'Y', 'Z', 'sX', ... also with --crs EPSG:25832 (metres)
    rep = tmp_path / "i.html"
    code, _, err = cli("orient", "intersection", *pair, "--crs", "EPSG:25832", "--report", rep)
    assert code == 0, err
    assert _heading(rep) == [
        "id", "X [m]", "Y [m]", "Z [m]", "sX [m]", "sY [m]", "sZ [m]", "rays", "sigma0",
    ]  # fmt: skip


def test_without_a_crs_the_unit_is_not_named(cli, pair, tmp_path):
    rep = tmp_path / "i.html"
    code, _, err = cli("orient", "intersection", *pair, "--report", rep)
    assert code == 0, err
    assert _heading(rep)[1:4] == ["X", "Y", "Z"]
    assert "in the ground unit of the cameras" in rep.read_text(encoding="utf-8")
