"""Help texts tell what the command does (docs run).

``orient relative --help`` said of ``-o/--output``: "Output CSV (default: stdout)", the
shared help of the point commands; but without ``-o`` it writes no CSV at all (its stdout is
the summary), as docs/cli.md says: ``-o`` writes the model coordinates.
"""

from __future__ import annotations

import numpy as np

import photogeom as pg


def _matches(path):
    io = pg.InteriorOrientation(100.0, unit="mm")
    eo1 = pg.ExteriorOrientation(0.0, 0.0, 1000.0, 0.0, 0.0, 0.0)
    eo2 = pg.ExteriorOrientation(400.0, 10.0, 1005.0, *np.radians([1.0, -2.0, 3.0]))
    rng = np.random.default_rng(1)
    g = np.c_[rng.uniform(-300, 700, 12), rng.uniform(-400, 400, 12), rng.uniform(0, 50, 12)]
    a, b = pg.project(g, io, eo1), pg.project(g, io, eo2)
    rows = "".join(f"p{i},{a[i, 0]},{a[i, 1]},{b[i, 0]},{b[i, 1]}\n" for i in range(12))
    path.write_text("id,x1,y1,x2,y2\n" + rows, encoding="utf-8")


def test_orient_relative_output_help_says_what_happens_without_it(cli, tmp_path):
    code, out, _ = cli("orient", "relative", "--help")
    assert code == 0
    block = out[out.index("-o, --output") :]
    block = " ".join(block[: block.index("--output-cameras")].split())
    assert "default: stdout" not in block
    assert "model coordinates" in block and "not written" in block
    matches = tmp_path / "m.csv"
    _matches(matches)
    code, out, err = cli("orient", "relative", matches, "--f", "100")
    assert code == 0, err
    assert "id,X,Y,Z" not in out  # no CSV without -o
    target = tmp_path / "model.csv"
    code, out, err = cli("orient", "relative", matches, "--f", "100", "-o", target)
    assert code == 0, err
    assert "id,X,Y,Z,sX,sY,sZ" in target.read_text(encoding="utf-8")
