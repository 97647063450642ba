"""``rpc fit`` and ``rpc refine`` wrote their outputs over their inputs:
``rpc fit ctl.csv --report ctl.csv`` replaced the control points with the HTML report and
``rpc refine IMG_RPC.TXT ctl.csv --report IMG_RPC.TXT`` the vendor RPC, exit 0. An output
naming an input is now refused before the computation, as in the other estimating
commands."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.rpc.readers import read_rpc

IKONOS = Path(datasets.__file__).parent / "data" / "rpc" / "rpc_IKONOS.txt"


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    rpc = read_rpc(IKONOS)
    rng = np.random.default_rng(0)
    u = rng.uniform(-0.5, 0.5, size=(60, 3))
    lon = rpc.long_off + u[:, 0] * rpc.long_scale
    lat = rpc.lat_off + u[:, 1] * rpc.lat_scale
    h = rpc.height_off + u[:, 2] * rpc.height_scale
    col, row = np.asarray(rpc.project(lon, lat, h))
    lines = ["id,lon,lat,h,col,row"]
    for k in range(60):
        lines.append(",".join(map(repr, [k, *(float(v[k]) for v in (lon, lat, h, col, row))])))
    ctl = tmp_path / "ctl.csv"
    ctl.write_text("\n".join(lines) + "\n")
    vendor = tmp_path / "IMG_RPC.TXT"
    shutil.copyfile(IKONOS, vendor)
    return {"ctl": ctl, "rpc": vendor}


@pytest.mark.parametrize("option", ["--report", "-o"])
def test_rpc_fit_keeps_its_control_points(cli, files, option):
    before = files["ctl"].read_bytes()
    code, _, err = cli("rpc", "fit", files["ctl"], option, files["ctl"])
    assert code == 2
    assert "is the input file POINTS" in err
    assert files["ctl"].read_bytes() == before


@pytest.mark.parametrize("target", ["rpc", "ctl"])
@pytest.mark.parametrize("option", ["--report", "-o"])
def test_rpc_refine_keeps_its_inputs(cli, files, option, target):
    before = files[target].read_bytes()
    code, _, err = cli("rpc", "refine", files["rpc"], files["ctl"], option, files[target])
    assert code == 2
    assert "is the input file " + ("RPC_FILE" if target == "rpc" else "POINTS") in err
    assert files[target].read_bytes() == before


def test_other_outputs_are_written(cli, files, tmp_path: Path):
    out = tmp_path / "refined_RPC.TXT"
    code, _, err = cli("rpc", "refine", files["rpc"], files["ctl"], "-o", out)
    assert code == 0, err
    assert out.is_file()
