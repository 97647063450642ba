"""`grid fit` / `grid apply` read numbers by the rule of every photogeom reader
Python's ``1_0`` digit grouping and non-ASCII digits are not numbers."""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.calibration import fit_grids, save_grids
from photogeom.cli import grid as gridcli
from photogeom.errors import FileFormatError


@pytest.mark.parametrize("arrow_cells", [20_000, 1])
@pytest.mark.parametrize(
    ("cell", "shown"), [("1_0", "'1_0'"), ("\u0663", "'\u0663'"), ("\u00a05", "'\\xa05'")]
)
def test_python_only_numbers_are_refused(tmp_path, monkeypatch, arrow_cells, cell, shown):
    monkeypatch.setattr(gridcli, "ARROW_CELLS", arrow_cells)
    p = tmp_path / "r.csv"
    p.write_text(f"image_id,u,v\nA,1,2\n# c\nA,{cell},2\nA,x,2\n", encoding="utf-8")
    _, columns, col, lines = gridcli._read_csv(p, ("image_id", "u", "v"))
    with pytest.raises(FileFormatError) as info:
        gridcli._numbers(p, columns[col["u"]], "u", lines)
    assert str(info.value) == f"{p}: line 4, column u: not a number ({shown})"
    # decimal numbers with blanks around them stay numbers
    assert gridcli._numbers(p, [" 1.5", "2e3\t", "+.5"], "u", lines).tolist() == [1.5, 2e3, 0.5]


def test_cli_fit_and_apply_refuse_them(cli, tmp_path):
    rng = np.random.default_rng(1)
    rows = [f"A,{a:.2f},{b:.2f},0.1,0.2" for a, b in rng.uniform(0, [299, 199], (100, 2))]
    res = tmp_path / "res.csv"
    res.write_text("image_id,u,v,rx,ry\n" + "\n".join(rows) + "\nA,1_0,5,0.1,0.2\n")
    code, _, err = cli(
        "grid", "fit", res, "--image-size", "300x200", "--folds", "0", "-o", tmp_path / "g.npz"
    )
    assert code != 0 and "res.csv: line 102, column u: not a number ('1_0')" in err
    uv = rng.uniform(0, [299, 199], (60, 2))
    save_grids(tmp_path / "g.npz", fit_grids({"A": (uv, uv * 0)}, (300, 200), 100.0, folds=0))
    obs = tmp_path / "obs.csv"
    obs.write_text("image_id,u,v\nA,10,\u0663\n", encoding="utf-8")
    code, _, err = cli("grid", "apply", tmp_path / "g.npz", obs)
    assert code != 0 and "obs.csv: line 2, column v: not a number ('\u0663')" in err
