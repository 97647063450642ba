"""The applying commands wrote ``-o`` over the model they apply (exit 0):
``transform apply s.json pts.csv -o s.json`` replaced the parameters with points, likewise
the RPC of ``rpc project|localize``, the grids file of ``grid apply``, the ``--camera`` of
``camera project``, and ``grid fit res.csv -o res.csv`` the residuals with the grids. Each
is refused now before anything is read; ``-o`` onto the points stays allowed (they are read
whole before the output replaces them)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.camera import ExteriorOrientation, InteriorOrientation

RPC = Path(datasets.__file__).parent / "data" / "rpc" / "rpc_IKONOS.txt"
FIDUCIALS = datasets.path("lecture_fiducials")


def _refused(cli, args, victim: Path, name: str) -> None:
    before = victim.read_bytes()
    code, _, err = cli(*args)
    assert code == 2, err
    assert f"--output {victim} is the input file {name}" in err
    assert victim.read_bytes() == before


def test_transform_apply(cli, tmp_path: Path):
    params = tmp_path / "s.json"
    code, _, err = cli("transform", "estimate", "similarity2d", FIDUCIALS,
                       "--output-params", params)
    assert code == 0, err
    _refused(cli, ("transform", "apply", params, FIDUCIALS, "-o", params), params, "PARAMS")
    pts = tmp_path / "pts.csv"
    shutil.copyfile(FIDUCIALS, pts)
    code, _, err = cli("transform", "apply", params, pts, "-o", pts)  # allowed, as before
    assert code == 0, err


@pytest.mark.parametrize("command", ["project", "localize"])
def test_rpc_project_and_localize(cli, tmp_path: Path, command):
    rpc = tmp_path / "IMG_RPC.TXT"
    shutil.copyfile(RPC, rpc)
    pts = tmp_path / "pts.csv"
    pts.write_text("id,lon,lat,h\n1,-56.17,-34.90,30\n" if command == "project"
                   else "id,col,row\n1,100,200\n")
    extra = ("--height", "30") if command == "localize" else ()
    _refused(cli, ("rpc", command, rpc, pts, "-o", rpc, *extra), rpc, "RPC_FILE")


def test_grid_fit_and_apply(cli, tmp_path: Path):
    rng = np.random.default_rng(2)
    res = tmp_path / "res.csv"
    rows = ["image_id,u,v,rx,ry"] + [
        f"{k % 2},{u:.3f},{v:.3f},{a:.3f},{b:.3f}"
        for k, (u, v, a, b) in enumerate(rng.uniform([0, 0, -1, -1], [999, 799, 1, 1],
                                                     size=(400, 4)))
    ]
    res.write_text("\n".join(rows) + "\n")
    _refused(cli, ("grid", "fit", res, "--image-size", "1000x800", "--spacing", "250", "-o",
                   res), res, "RESIDUALS")
    grids = tmp_path / "g.npz"
    code, _, err = cli("grid", "fit", res, "--image-size", "1000x800", "--spacing", "250",
                       "--folds", "0", "-o", grids)
    assert code == 0, err
    obs = tmp_path / "obs.csv"
    obs.write_text("image_id,u,v\n0,100,200\n")
    _refused(cli, ("grid", "apply", grids, obs, "-o", grids), grids, "GRIDS_FILE")


def test_camera_project(cli, tmp_path: Path):
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"interior": InteriorOrientation(f=152.0).to_dict(),
                               "exterior": ExteriorOrientation(0.0, 0.0, 1000.0).to_dict()}))
    pts = tmp_path / "ground.csv"
    pts.write_text("id,X,Y,Z\n1,10,20,0\n2,-30,5,1\n")
    _refused(cli, ("camera", "project", pts, "--camera", cam, "-o", cam), cam, "--camera")


def test_cloud_transform_keeps_its_parameters(cli, tmp_path: Path):
    """cloud transform c.las p.json --params p.json wrote the cloud over the parameters."""
    laspy = pytest.importorskip("laspy")
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = [0.001] * 3
    header.offsets = [0.0] * 3
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.random.default_rng(0).uniform(0, 100, (3, 200))
    cloud = tmp_path / "c.las"
    las.write(cloud)
    params = tmp_path / "p.json"
    code, _, err = cli("orient", "absolute", datasets.path("kraus_absolute_orientation"),
                       "--output-params", params)
    assert code == 0, err
    before = params.read_bytes()
    code, _, err = cli("cloud", "transform", cloud, params, "--params", params)
    assert code == 2
    assert f"OUTPUT {params} is the --params file" in err
    assert params.read_bytes() == before


def test_grid_fit_keeps_the_files_of_its_block(cli, tmp_path: Path):
    """grid fit BLOCK -o BLOCK/observations.csv wrote the grids over the block's file."""
    from photogeom.bundle import read_bal, write_csv_block

    block = tmp_path / "block"
    write_csv_block(read_bal(Path(datasets.__file__).parent / "data" / "bundle"
                             / "dubrovnik-3-7-pre.txt"), block)
    victim = block / "observations.csv"
    before = victim.read_bytes()
    code, _, err = cli("grid", "fit", block, "--spacing", "200", "-o", victim)
    assert code == 2
    assert f"--output {victim} is the input file RESIDUALS (observations.csv of the block)" in err
    assert victim.read_bytes() == before
