"""`camera dlt estimate` had --sigma-col but no --sigma (orient resection has both):
one standard deviation for every image point could only be given as a column."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import photogeom as pg


def _files(tmp_path: Path) -> tuple[Path, Path, Path]:
    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    eo = pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10)
    rng = np.random.default_rng(0)
    g = np.column_stack([rng.uniform(1050, 1550, 12), rng.uniform(750, 1100, 12),
                         rng.uniform(100, 300, 12)])
    xy = pg.project(g, io, eo) + rng.normal(0, 0.003, (12, 2))
    ground, img, img_s = tmp_path / "g.csv", tmp_path / "i.csv", tmp_path / "s.csv"
    ground.write_text("id,X,Y,Z\n" + "".join(
        f"P{i}," + ",".join(repr(float(v)) for v in g[i]) + "\n" for i in range(12)))
    img.write_text("id,x,y\n" + "".join(
        f"P{i}," + ",".join(repr(float(v)) for v in xy[i]) + "\n" for i in range(12)))
    img_s.write_text("id,x,y,s\n" + "".join(
        f"P{i}," + ",".join(repr(float(v)) for v in xy[i]) + ",0.003\n" for i in range(12)))
    return ground, img, img_s


def test_sigma_is_a_sigma_column_of_one_value(cli, tmp_path: Path):
    ground, img, img_s = _files(tmp_path)
    code, out, err = cli("camera", "dlt", "estimate", ground, img, "--sigma", "0.003", "--json")
    assert code == 0, err
    a = json.loads(out)
    code, out, err = cli("camera", "dlt", "estimate", ground, img_s, "--sigma-col", "s",
                         "--json")
    assert code == 0, err
    b = json.loads(out)
    assert a["sigma0"] == b["sigma0"] and a["parameters"] == b["parameters"]
    code, _, err = cli("camera", "dlt", "estimate", ground, img_s, "--sigma-col", "s",
                       "--sigma", "1")
    assert code == 2 and "--sigma or --sigma-col" in err
    code, _, err = cli("camera", "dlt", "estimate", ground, img, "--sigma", "-1")
    assert code == 2 and err.startswith("error: --sigma: ")
