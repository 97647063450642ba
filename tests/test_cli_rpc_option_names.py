"""`rpc fit` / `rpc refine` named the library's keywords in their errors ('sigma:',
'order must be', 'regularization must be') where the user typed --sigma, --order,
--regularization."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets

IKONOS = datasets.path("lecture_fiducials").parent / "rpc" / "rpc_IKONOS.txt"


@pytest.fixture(scope="module")
def gcps(tmp_path_factory) -> Path:
    from photogeom.rpc import read_rpc

    rpc = read_rpc(IKONOS)
    rng = np.random.default_rng(0)
    lon, lat = rng.uniform(-56.2, -56.14, 40), rng.uniform(-34.94, -34.87, 40)
    h = rng.uniform(0, 60, 40)
    col, row = rpc.project(lon, lat, h)
    p = tmp_path_factory.mktemp("g") / "gcp.csv"
    p.write_text("id,lon,lat,h,col,row\n" + "".join(
        f"{i}," + ",".join(repr(float(v)) for v in vals) + "\n"
        for i, vals in enumerate(zip(lon, lat, h, col + 0.5, row - 0.3))))
    return p


@pytest.mark.parametrize(("args", "expected"), [
    (("rpc", "refine", str(IKONOS), "{g}", "--sigma", "-1"), "error: --sigma: "),
    (("rpc", "fit", "{g}", "--sigma", "0"), "--sigma must be a positive number of pixels"),
    (("rpc", "fit", "{g}", "--order", "4"), "--order must be 1, 2 or 3"),
    (("rpc", "fit", "{g}", "--regularization", "-1"), "--regularization must be >= 0"),
])
def test_rpc_errors_name_the_options(cli, gcps, args, expected):
    code, _, err = cli(*[a.format(g=gcps) for a in args])
    assert code == 2 and expected in err, err


@pytest.mark.parametrize("height", ["nan", "inf"])
def test_localize_height_not_finite_names_the_option(cli, tmp_path: Path, height):
    pts = tmp_path / "px.csv"
    pts.write_text("id,col,row\n1,100,200\n")
    code, _, err = cli("rpc", "localize", IKONOS, pts, "--height", height)
    assert code == 2 and err.startswith(f"error: --height {height}: "), err
