"""Image ids round-trip through the block folder, ``grid fit`` and ``grid apply`` exactly.

A block folder's ``" im0 "`` (quoted: white space kept) was fitted as image ``" im0 "``, but
``grid apply grids block/observations.csv`` stripped the id to ``im0`` ("no grid ... for
image(s) im0"), and its writer wrote quoted cells unquoted (``" im0 "`` came back as
``im0``, ``"7"`` as the integer ``7``). Quoted cells are now their text exactly in the
``grid`` readers, as in a block folder, and are written quoted again.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import fit_grids, load_grids, save_grids

IDS = [" im0 ", " im1 ", "#im2", "a,b", 'say "x"', "im5", "im6", "im7"]


@pytest.fixture(scope="module")
def block_dir(tmp_path_factory) -> Path:
    """A small simulated CSV block whose image ids need quotes."""
    b = pg.simulate.uav_block(
        "FC300S", seed=5, strips=2, images_per_strip=4, tie_points_per_image=60
    ).block
    names = np.array(IDS[: b.n_images], dtype=object).astype(str)
    o = b.observations
    b = b.replace(
        image_ids=names,
        observations=type(o)(names[b.obs_image], o.point_ids, o.uv, o.sigma),
    )
    d = tmp_path_factory.mktemp("ids") / "block"
    pg.bundle.write_csv_block(b, d)
    return d


def test_fit_block_then_apply_its_observations(cli, tmp_path, block_dir):
    grids = tmp_path / "g.json"
    code, _, err = cli("grid", "fit", block_dir, "-o", grids, "--spacing", "400")
    assert code == 0, err
    assert sorted(load_grids(grids)) == sorted(IDS)
    out = tmp_path / "corrected.csv"
    code, _, err = cli("grid", "apply", grids, block_dir / "observations.csv", "-o", out)
    assert code == 0, err  # was: no grid in g.json for image(s) im0, im1
    # the corrected observations replace the block's: every id still names its image
    again = tmp_path / "again"
    again.mkdir()
    for f in ("cameras.csv", "images.csv", "points.csv"):
        (again / f).write_bytes((block_dir / f).read_bytes())
    (again / "observations.csv").write_bytes(out.read_bytes())
    before = pg.bundle.read_csv_block(block_dir)
    after = pg.bundle.read_csv_block(again)
    assert after.observations.image_ids.tolist() == before.observations.image_ids.tolist()
    assert after.observations.point_ids.tolist() == before.observations.point_ids.tolist()
    assert not np.array_equal(after.observations.uv, before.observations.uv)


def _grids(tmp_path: Path, keys) -> Path:
    rng = np.random.default_rng(1)
    per_image = {}
    for k in keys:
        uv = rng.uniform([0, 0], [999, 799], size=(200, 2))
        per_image[k] = (uv, 0.5 * np.sin(uv / 300.0) + rng.normal(0, 0.1, size=(200, 2)))
    f = tmp_path / "g.json"
    save_grids(f, fit_grids(per_image, (1000, 800), 250.0, folds=0))
    return f


def test_apply_keeps_quoted_cells_quoted(cli, tmp_path):
    grids = _grids(tmp_path, [" a ", "7", "b"])
    obs = tmp_path / "obs.csv"
    obs.write_text(
        'image_id,point_id,u,v,note\n" a ",1,10,20,x\n"7","2",30,40," y "\n b ,3,50,60,z\n'
    )
    out = tmp_path / "out.csv"
    code, _, err = cli("grid", "apply", grids, obs, "-o", out)
    assert code == 0, err
    rows = [ln.split(",") for ln in out.read_text().splitlines()[1:]]
    assert [r[0] for r in rows] == ['" a "', '"7"', " b "]  # unquoted: as read
    assert [r[1] for r in rows] == ["1", '"2"', "3"]
    assert [r[4] for r in rows] == ["x", '" y "', "z"]


def test_fit_residuals_csv_keeps_quoted_ids(cli, tmp_path):
    rng = np.random.default_rng(2)
    uv = rng.uniform([0, 0], [999, 799], size=(300, 2))
    r = 0.3 * np.sin(uv / 300.0)
    lines = ["image_id,u,v,rx,ry"]
    for k, ((u, v), (x, y)) in enumerate(zip(uv.tolist(), r.tolist())):
        lines.append(f'{[chr(34) + " im0 " + chr(34), "im1"][k % 2]},{u},{v},{x},{y}')
    res = tmp_path / "res.csv"
    res.write_text("\n".join(lines) + "\n")
    grids = tmp_path / "g.json"
    code, _, err = cli(
        "grid", "fit", res, "-o", grids, "--image-size", "1000x800", "--spacing", "250"
    )
    assert code == 0, err
    assert sorted(load_grids(grids)) == [" im0 ", "im1"]


@pytest.mark.parametrize(
    "body",
    [
        '" a ",1\n b ,2\n',  # whole quoted cells: split at once
        '" a ",1\n b ,2\n"c,d",3\n',  # a cell with a comma: the csv module
        '" a ",1\n b ,2\n"c\nd",3\n',  # a quoted line break: the whole file line-wise
    ],
)
def test_reader_marks_quoted_cells_on_every_path(tmp_path, body):
    from photogeom.cli.grid import _ids, _read_csv

    f = tmp_path / "x.csv"
    f.write_text("image_id,n\n" + body)
    quoted: list = []
    _, columns, col, _ = _read_csv(f, ("image_id",), None, quoted)
    ids = _ids(columns[col["image_id"]], quoted[col["image_id"]])
    assert ids[:2] == [" a ", "b"]
    if len(ids) > 2:
        assert ids[2] in ("c,d", "c\nd")


def test_apply_minus_zero_finds_the_grid_of_integer_image_zero(cli, tmp_path):
    """A block folder reads an observation's -0 as image 0 of an integer column; grid apply
    found no grid for it ("no grid ... for image(s) -0") although grid fit had fitted it."""
    grids = _grids(tmp_path, [0, 1])
    obs = tmp_path / "obs.csv"
    obs.write_text("image_id,point_id,u,v\n-0,1,10,20\n1,2,30,40\n")
    code, _, err = cli("grid", "apply", grids, obs, "-o", tmp_path / "out.csv")
    assert code == 0, err
    (tmp_path / "t").mkdir()
    text_grids = _grids(tmp_path / "t", ["0", "1"])
    code, _, err = cli("grid", "apply", text_grids, obs, "-o", tmp_path / "out2.csv")
    assert code != 0 and "for image(s) -0" in err  # the text "0" is another id


def test_exclude_takes_quoted_ids(cli, tmp_path, block_dir):
    """--exclude " im0 " was stripped to im0: "no image im0 (its images:  im0 , ...)"; a
    quoted id is now taken exactly, as in the CSV, and the message quotes the ids."""
    grids = tmp_path / "g.json"
    code, _, err = cli("grid", "fit", block_dir, "-o", grids, "--spacing", "400",
                       "--exclude", '" im0 ","a,b"')  # fmt: skip
    assert code == 0, err
    assert sorted(load_grids(grids)) == sorted(set(IDS) - {" im0 ", "a,b"})
    code, _, err = cli("grid", "fit", block_dir, "-o", grids, "--spacing", "400",
                       "--exclude", " im0 ")  # fmt: skip
    assert code == 2
    assert 'no image im0' in err and '" im0 "' in err and '"a,b"' in err
