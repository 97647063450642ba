"""`photogeom grid fit | apply`: ids, quoting, empty input, CLI words."""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from photogeom.calibration import GridLayout, ResidualGrid, save_grids

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

W, H = 90, 60


def _grid(seed: int = 0) -> ResidualGrid:
    rng = np.random.default_rng(seed)
    layout = GridLayout(W, H, 30)
    return grid_with_nodes(layout, rng.normal(0, 1, (*layout.shape, 2)))


def test_apply_matches_csv_text_ids_to_integer_grid_ids(cli, tmp_path):
    grids = {0: _grid(0), 1: _grid(1)}  # a simulated block's integer ids
    path = save_grids(tmp_path / "g.npz", grids, std=False)
    obs = tmp_path / "obs.csv"
    obs.write_text("image_id,u,v\n1,10.5,20.25\n0,3,4\n")
    code, text, err = cli("grid", "apply", path, obs)
    assert code == 0, err
    rows = [r.split(",") for r in text.strip().splitlines()[1:]]
    for (iid, u, v), key in zip(rows, (1, 0)):
        assert iid == str(key)
        uv = np.array([[10.5, 20.25]] if key == 1 else [[3.0, 4.0]])
        want = uv + grids[key].evaluate(uv)
        assert (float(u), float(v)) == pytest.approx(tuple(want[0]), abs=1e-12)


cell_text = st.text(
    st.characters(min_codepoint=32, max_codepoint=0x2FF) | st.sampled_from(',"\n\r\t')
)


@settings(
    max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(cells=st.lists(st.tuples(cell_text, cell_text), min_size=1, max_size=4))
def test_apply_writes_csv_that_reads_back(cli, tmp_path, cells):
    """Kept columns with commas, quotes and line breaks: the output reads back with
    csv.reader, cell for cell, and through grid apply itself."""
    path = save_grids(tmp_path / "g.json", {"A": _grid(3)}, std=False)
    rows = [[name, "A", str(10 + k), str(5 + k), note] for k, (name, note) in enumerate(cells)]
    rows = [r for r in rows if any(c.strip() for c in r)]
    obs = tmp_path / "obs.csv"
    with open(obs, "w", newline="", encoding="utf-8") as fh:
        csv.writer(fh).writerows([["name", "image_id", "u", "v", "note, with comma"], *rows])
    out = tmp_path / "out.csv"
    code, _, err = cli("grid", "apply", path, obs, "-o", out)
    assert code == 0, err
    with open(out, newline="", encoding="utf-8") as fh:
        back = list(csv.reader(fh))
    assert back[0] == ["name", "image_id", "u", "v", "note, with comma"]
    assert [[r[0], r[1], r[4]] for r in back[1:]] == [[r[0], r[1], r[4]] for r in rows]
    uv = np.array([[float(r[2]), float(r[3])] for r in rows])
    got = np.array([[float(r[2]), float(r[3])] for r in back[1:]])
    np.testing.assert_array_equal(got, _grid(3).correct(uv))
    code, _, err = cli("grid", "apply", path, out, "-o", tmp_path / "again.csv")
    assert code == 0, err
    with open(tmp_path / "again.csv", newline="", encoding="utf-8") as fh:
        again = list(csv.reader(fh))
    assert [[r[0], r[4]] for r in again[1:]] == [[r[0], r[4]] for r in rows]


@pytest.mark.parametrize("extra", [(), ("--report", "r.html")])
def test_fit_refuses_a_csv_without_rows(cli, tmp_path, extra):
    csv_path = tmp_path / "empty.csv"
    csv_path.write_text("image_id,u,v,rx,ry\n\n")
    out = tmp_path / "g.npz"
    code, _, err = cli(
        "grid", "fit", csv_path, "--image-size", "90x60", "-o", out,
        *[tmp_path / a if a.endswith(".html") else a for a in extra],
    )  # fmt: skip
    assert code == 2 and err.startswith("error: no residuals in") and str(csv_path) in err
    assert not out.exists() and not (tmp_path / "r.html").exists()


@pytest.mark.parametrize("command", ["fit", "apply"])
def test_non_finite_numbers_named_by_their_file_line(cli, tmp_path, command):
    """Line 7 of the file (a blank line and a quoted line break before it), whatever the
    image's own row count, in the words of the command that read it."""
    rows = [
        "image_id,u,v,rx,ry,note",
        "A,10,10,0,0,x",
        "",
        'B,20,20,0,0,"two',
        'lines"',
        "A,30,30,0,0,y",
        "A,inf,40,0,0,z",
    ]
    csv_path = tmp_path / "obs.csv"
    csv_path.write_text("\n".join(rows) + "\n")
    if command == "fit":
        args = ("grid", "fit", csv_path, "--image-size", "90x60", "-o", tmp_path / "g.npz")
    else:
        grids = save_grids(tmp_path / "g.json", {"A": _grid(), "B": _grid(1)}, std=False)
        args = ("grid", "apply", grids, csv_path, "-o", tmp_path / "out.csv")
    code, _, err = cli(*args)
    assert code == 2 and "line 7, column u: 'inf' is not a finite number" in err
    assert "before fitting" not in err
    assert not (tmp_path / "g.npz").exists() and not (tmp_path / "out.csv").exists()


def _noise_csv(path, n=200):
    """Noise only, on a grid finer than its data: no variance ratio fits (vce fails)."""
    rng = np.random.default_rng(0)
    uv = rng.uniform(0, 89, (n, 2)) * [1, 0.66]
    r = rng.normal(0, 1, (n, 2))
    lines = ["image_id,u,v,rx,ry"] + [f"A,{a},{b},{c},{d}" for a, b, c, d in np.hstack([uv, r])]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_fit_errors_in_cli_words(cli, tmp_path):
    """A ConvergenceError of the variance components speaks of options, not keywords."""
    csv_path = _noise_csv(tmp_path / "noise.csv")
    out = tmp_path / "g.npz"
    base = ("grid", "fit", csv_path, "--image-size", "90x60", "--folds", "0", "-o", out)
    code, _, err = cli(*base, "--spacing", "15", "--sigma-constraint", "vce")
    assert code == 2 and err.startswith("error:") and "variance components" in err
    assert "give --sigma-constraint, or a larger --spacing" in err
    assert "sigma_constraint" not in err
    code, _, err = cli(*base, "--spacing", "30", "--min-support", "-1")
    assert code == 2 and "--min-support must be 0 or more" in err
    assert not out.exists()


@pytest.mark.parametrize("cell", ["", "  ", '""'])
def test_fit_refuses_an_empty_image_id_naming_its_line(cli, tmp_path, cell):
    # the empty cell made an image called "" with a grid of its own (exit 0)
    rng = np.random.default_rng(2)
    rows = [f"A,{u:.2f},{v:.2f},0.1,-0.1" for u, v in rng.uniform(0, [89, 59], (12, 2))]
    rows.insert(4, f"{cell},40,30,0.2,0.1")
    path = tmp_path / "v.csv"
    path.write_text("image_id,u,v,rx,ry\n" + "\n".join(rows) + "\n")
    out = tmp_path / "g.npz"
    code, _, err = cli("grid", "fit", path, "--image-size", f"{W}x{H}", "--spacing", "30",
                       "-o", out)
    assert code == 2, err
    assert f"{path}: empty image_id on line(s) 6; give each row the id of its image" in err, err
    assert not out.exists()
