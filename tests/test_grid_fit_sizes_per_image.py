"""``grid fit residuals.csv --image-size SIZES.csv``: residuals of images of several sizes
(cameras of different formats) get grids of each image's size. Before, ``--image-size``
was one ``WIDTHxHEIGHT`` for all: the larger images' rows were refused as outside the image,
or every grid took the largest size (the smaller images' grids of the wrong extent)."""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.calibration import load_grids

SIZES = {"a": (800, 600), "b": (1200, 900)}


@pytest.fixture
def residuals(tmp_path):
    rng = np.random.default_rng(1)
    rows = ["image_id,u,v,rx,ry"]
    for img, (w, h) in SIZES.items():
        u, v = rng.uniform(0, w - 1, 300), rng.uniform(0, h - 1, 300)
        rx = 0.3 * (u / w - 0.5) + rng.normal(0, 0.1, 300)
        ry = 0.2 * (v / h - 0.5) + rng.normal(0, 0.1, 300)
        cells = np.column_stack([u, v, rx, ry])
        rows += [img + "," + ",".join(f"{x:.17g}" for x in row) for row in cells]
    path = tmp_path / "res.csv"
    path.write_text("\n".join(rows) + "\n")
    return path


def test_each_image_gets_the_grid_of_its_own_size(cli, tmp_path, residuals):
    sizes = tmp_path / "sizes.csv"
    sizes.write_text("image_id,width,height\n" + "".join(f"{k},{w},{h}\n" for k, (w, h) in
                                                          SIZES.items()))  # fmt: skip
    code, _, err = cli("grid", "fit", residuals, "--image-size", sizes, "--spacing", "200",
                       "-o", tmp_path / "g.json")  # fmt: skip
    assert code == 0, err
    grids = load_grids(tmp_path / "g.json")
    assert {k: g.image_size for k, g in grids.items()} == SIZES
    # the same grids as each image's rows fitted alone at its size
    lines = residuals.read_text().splitlines()
    for k, (w, h) in SIZES.items():
        alone = tmp_path / f"{k}.csv"
        alone.write_text("\n".join([lines[0], *(ln for ln in lines[1:] if ln.startswith(k + ","))]))
        code, _, err = cli("grid", "fit", alone, "--image-size", f"{w}x{h}", "--spacing", "200",
                           "-o", tmp_path / f"{k}.json")  # fmt: skip
        assert code == 0, err
        np.testing.assert_allclose(grids[k].nodes, load_grids(tmp_path / f"{k}.json")[k].nodes,
                                   rtol=0, atol=1e-12)  # fmt: skip
    # one size for all: the larger image's rows are outside, and the fix names SIZES.csv
    code, _, err = cli("grid", "fit", residuals, "--image-size", "800x600", "--spacing", "200",
                       "-o", tmp_path / "one.json")  # fmt: skip
    assert code == 2 and "outside the 800 x 600 px image" in err and "SIZES.csv" in err


def test_an_image_without_a_size_is_refused_by_name(cli, tmp_path, residuals):
    sizes = tmp_path / "sizes.csv"
    sizes.write_text("image_id,width,height\na,800,600\n")
    code, _, err = cli("grid", "fit", residuals, "--image-size", sizes, "--spacing", "200",
                       "-o", tmp_path / "g.json")  # fmt: skip
    assert code == 2 and "gives no size for image 'b'" in err and "--exclude" in err
    code, _, err = cli("grid", "fit", residuals, "--image-size", sizes, "--spacing", "200",
                       "--exclude", "b", "-o", tmp_path / "g.json")  # fmt: skip
    assert code == 0, err
    assert list(load_grids(tmp_path / "g.json")) == ["a"]
