"""Output files that cannot be written: one ``error:`` line, exit code 2, nothing changed.

Every command that writes files is run with each of its outputs pointing at an unwritable
destination (a directory, a read-only file, a path below a regular file) while its other
outputs point at existing files: the command must fail with one line, exit code 2, and leave
every existing file as it was (several outputs of one command are written all-or-nothing).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
import photogeom.io
from photogeom.examples.rpc import simulated_control
from photogeom.io import write_points

FIDUCIALS = str(pg.datasets.path("lecture_fiducials"))
LIDAR = str(pg.datasets.path("lidar_wang2014"))
WV2 = str(pg.datasets.path("worldview2"))
CAMERA = ["--f", "152.14", "--x0", "0.008", "--y0", "-0.12"]
OLD = "old content\n"


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("inputs")
    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    rng = np.random.default_rng(0)
    g = np.column_stack(
        [rng.uniform(1050, 1550, 12), rng.uniform(750, 1100, 12), rng.uniform(100, 300, 12)]
    )
    files: dict[str, Path] = {}
    eos = [
        pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10),
        pg.ExteriorOrientation.from_degrees(1600, 820, 1620, -1, 2, 8),
    ]
    for k, eo in enumerate(eos):
        xy = pg.project(g, io, eo)
        ids = [f"P{i}" for i in range(12)]
        write_points(d / f"control{k}.csv", ids, np.column_stack([g, xy]),
                     ["X", "Y", "Z", "x", "y"])  # fmt: skip
        write_points(d / f"image{k}.csv", ids, xy, ["x", "y"])
        cam = d / f"cam{k}.json"
        cam.write_text(
            '{"interior": ' + _json(io.to_dict()) + ', "exterior": ' + _json(eo.to_dict()) + "}"
        )
        files[f"control{k}"], files[f"image{k}"], files[f"cam{k}"] = (
            d / f"control{k}.csv", d / f"image{k}.csv", cam,
        )  # fmt: skip
    ground = d / "ground.csv"
    ground.write_text("id,lon,lat,h\np1,-0.33,45.65,100\np2,-0.30,45.66,50\n")
    pixels = d / "pixels.csv"
    pixels.write_text("id,col,row,h\np1,100,200,100\np2,300,400,50\n")
    _, gr, true, observed = simulated_control()
    control = d / "rpc_control.csv"
    write_points(control, [f"P{i}" for i in range(24)],
                 np.column_stack([gr, np.vstack([observed[:4], true[4:]])]),
                 ["lon", "lat", "h", "col", "row"],
                 extra={"role": ["control"] * 4 + ["check"] * 20})  # fmt: skip
    rpc = pg.read_rpc(WV2)
    c, r, h = rng.uniform(0, 28000, 30), rng.uniform(0, 20000, 30), rng.uniform(0, 500, 30)
    lon, lat = rpc.localize(c, r, h)
    many = d / "rpc_many.csv"
    write_points(many, [f"Q{i}" for i in range(30)], np.column_stack([lon, lat, h, c, r]),
                 ["lon", "lat", "h", "col", "row"])  # fmt: skip
    files["rpc_many"] = many
    params = d / "similarity.json"
    pairs = pg.io.read_point_pairs(FIDUCIALS)
    fit = pg.estimate_transform("similarity2d", pairs.source, pairs.target)
    params.write_text('{"model_parameters": ' + _json(fit.transform.to_dict()) + "}")
    new_pts = d / "new.csv"
    new_pts.write_text("id,x,y\na,1,2\nb,3,4\n")
    files.update(ground=ground, pixels=pixels, rpc_control=control, params=params,
                 new_points=new_pts)  # fmt: skip
    return files


def _json(d) -> str:
    import json

    return json.dumps(d)


# (name, arguments before the outputs, output options)
COMMANDS = [
    ("transform estimate", lambda f: ["transform", "estimate", "similarity2d", FIDUCIALS],
     ["--output-params", "--report"]),
    ("transform apply", lambda f: ["transform", "apply", f["params"], f["new_points"]], ["-o"]),
    ("orient absolute", lambda f: ["orient", "absolute", LIDAR], ["--report"]),
    ("orient absolute --compare", lambda f: ["orient", "absolute", LIDAR, "--compare"],
     ["--report"]),
    ("orient resection", lambda f: ["orient", "resection", f["control0"], *CAMERA],
     ["--output-params", "--report"]),
    ("orient intersection", lambda f: ["orient", "intersection", f["image0"], f["image1"],
                                       "--camera", f["cam0"], "--camera", f["cam1"]],
     ["-o", "--report"]),
    ("camera project", lambda f: ["camera", "project", f["control0"], *CAMERA, "--eo",
                                  "1114,862,1600,2,3,10"], ["-o"]),
    ("camera dlt estimate", lambda f: ["camera", "dlt", "estimate", f["control0"]],
     ["--output-params", "--report"]),
    ("rpc project", lambda f: ["rpc", "project", WV2, f["ground"]], ["-o"]),
    ("rpc localize", lambda f: ["rpc", "localize", WV2, f["pixels"]], ["-o"]),
    ("rpc refine", lambda f: ["rpc", "refine", WV2, f["rpc_control"], "--model", "shift"],
     ["-o", "--report"]),
    ("rpc fit", lambda f: ["rpc", "fit", f["rpc_many"], "--order", "1"], ["-o"]),
    ("examples run", lambda f: ["examples", "run", "fiducials"], ["--report"]),
]  # fmt: skip

KINDS = ("directory", "read-only", "below-a-file")
# every output of every command, the three kinds of unwritable destination taken in turn
CASES = [
    (name, args, outs, bad, KINDS[k % len(KINDS)])
    for k, (name, args, outs, bad) in enumerate(
        (name, args, outs, bad) for name, args, outs in COMMANDS for bad in outs
    )
]


def _bad_destination(kind: str, directory: Path) -> Path:
    if kind == "directory":
        p = directory / "a_directory"
        p.mkdir()
        return p
    if kind == "read-only":
        p = directory / "read_only.out"
        p.write_text(OLD)
        p.chmod(0o444)
        return p
    p = directory / "plain_file"  # a path below a regular file
    p.write_text(OLD)
    return p / "out.txt"


def _snapshot(directory: Path) -> dict[str, str | None]:
    return {
        str(p.relative_to(directory)): (p.read_text() if p.is_file() else None)
        for p in sorted(directory.rglob("*"))
    }


@pytest.mark.parametrize(("name", "args", "outs", "bad", "kind"), CASES,
                         ids=[f"{c[0]} {c[3]} {c[4]}" for c in CASES])  # fmt: skip
def test_unwritable_output(cli, inputs, tmp_path, name, args, outs, bad, kind):
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    argv = list(args(inputs))
    for opt in outs:
        if opt == bad:
            argv += [opt, _bad_destination(kind, out_dir)]
        else:
            good = out_dir / f"existing{opt.strip('-')}.out"
            good.write_text(OLD)
            argv += [opt, good]
    before = _snapshot(out_dir)
    code, out, err = cli(*argv)
    assert code == 2, (out, err)
    # "cannot write", after the option's name where it is refused before the computation
    lines = err.strip().splitlines()
    assert len(lines) == 1 and re.match(r"error: (--[a-z-]+: )?cannot write", lines[0]), err
    assert _snapshot(out_dir) == before  # nothing written, nothing left behind


@pytest.mark.skipif(os.name != "posix", reason="POSIX resource limits")
def test_file_size_limit_is_one_error_line(tmp_path, inputs):
    """``ulimit -f``: the write fails with EFBIG (not a signal, not a traceback)."""
    import subprocess
    import sys

    target = tmp_path / "params.json"
    target.write_text(OLD)
    code = (
        "import resource, sys\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (64, 64))\n"
        "from photogeom.cli.main import main\n"
        f"main(['transform', 'estimate', 'similarity2d', {FIDUCIALS!r},"
        f" '--output-params', {str(target)!r}])\n"
    )
    env = dict(os.environ, PYTHONPATH=str(Path(pg.__file__).parents[1]))
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         timeout=120)  # fmt: skip
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "file-size limit" in lines[0], res.stderr
    assert target.read_text() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == ["params.json"]
