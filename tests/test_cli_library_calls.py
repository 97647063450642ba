"""Errors that told the command-line user to call the library: orient relative
"use method='independent'", grid fit "with border='linear' ...; try border='mean'", bundle
adjust "remove them with Block.drop_weak_points()", COLMAP "read with image_key='id'"."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import photogeom as pg


def test_relative_base_across_x_names_method_option(cli, tmp_path: Path):
    io = pg.InteriorOrientation(100.0, 0, 0)
    e1 = pg.ExteriorOrientation.from_degrees(0, 0, 1000, 0, 0, 0)
    e2 = pg.ExteriorOrientation.from_degrees(0, 300, 1000, 0, 0, 0)  # base along y
    rng = np.random.default_rng(1)
    g = np.column_stack([rng.uniform(-300, 300, 20), rng.uniform(-200, 500, 20),
                         rng.uniform(0, 100, 20)])
    a, b = pg.project(g, io, e1), pg.project(g, io, e2)
    m = tmp_path / "m.csv"
    m.write_text("id,x1,y1,x2,y2\n" + "".join(
        f"P{i}," + ",".join(repr(float(v)) for v in (*a[i], *b[i])) + "\n" for i in range(20)))
    code, _, err = cli("orient", "relative", m, "--f", "100")
    assert code == 2 and "use --method independent" in err and "method=" not in err, err


def test_grid_fit_collinear_names_border_option(cli, tmp_path: Path):
    res = tmp_path / "r.csv"
    res.write_text("image_id,u,v,rx,ry\n" + "".join(
        f"A,{u},{0.8 * u},0.1,0.2\n" for u in (100, 200, 400, 600, 800)))
    code, _, err = cli("grid", "fit", res, "--image-size", "1000x800", "-o", tmp_path / "g.npz",
                       "--border", "linear", "--folds", "0", "--spacing", "500")
    assert code == 2 and "with --border linear" in err and "try --border mean" in err, err


def test_weak_points_fix_is_in_the_files(cli, tmp_path: Path):
    root = tmp_path / "b"
    code, _, err = cli("bundle", "simulate", root, "--strips", "2", "--images-per-strip", "3",
                       "--json")
    assert code == 0, err
    obs = root / "observations.csv"
    lines = obs.read_text().splitlines()
    # a few rows of two images (one image is refused as such): points seen once
    head = [x for x in lines if x.startswith("#") or x.startswith("image_id")]
    rows = [x for x in lines if x not in head]
    first = rows[0].split(",")[0]
    other = [x for x in rows if x.split(",")[0] != first]
    obs.write_text("\n".join(head + rows[:6] + other[:6]) + "\n")
    code, _, err = cli("bundle", "adjust", root)
    assert code == 2 and "delete their rows from the block's files" in err
    assert "drop_weak_points" not in err, err


def test_colmap_image_key_phrase():
    from photogeom.cli.bundle import _CLI_WORDS

    assert ("read with image_key='id'", "read with --image-key id") in _CLI_WORDS
