"""Point CSVs from a pipe (`<(cat f.csv)`, `cat f.csv | photogeom ... /dev/stdin`): the
input can be read once, and the reader opens it for the header, the blocks and the
diagnostics; it used to report the pipe as empty."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.io import read_points

sys.path.insert(0, str(Path(__file__).parent))  # the tests' helper modules
from fifos import fifo_with

FIDUCIALS = datasets.path("lecture_fiducials")

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")


def test_read_points_from_a_named_pipe_equals_the_file(tmp_path: Path):
    data = Path(FIDUCIALS).read_bytes()
    from_file = read_points(FIDUCIALS, "x,y")
    from_pipe = read_points(fifo_with(tmp_path, data, "points.pipe"), "x,y")
    np.testing.assert_array_equal(from_pipe.coords, from_file.coords)
    assert list(from_pipe.ids) == list(from_file.ids)


def test_transform_apply_reads_points_from_a_pipe(cli, tmp_path: Path):
    params = tmp_path / "s.json"
    code, _, err = cli(
        "transform", "estimate", "similarity2d", FIDUCIALS, "--output-params", params
    )
    assert code == 0, err
    code, from_file, err = cli("transform", "apply", params, FIDUCIALS)
    assert code == 0, err
    fifo = fifo_with(tmp_path, Path(FIDUCIALS).read_bytes(), "points.pipe")
    code, from_pipe, err = cli("transform", "apply", params, fifo)
    assert code == 0, err

    def rows(text: str) -> list[str]:  # the comment line names the input path
        return [line for line in text.splitlines() if not line.startswith("#")]

    assert rows(from_pipe) == rows(from_file) and len(rows(from_file)) > 8


def test_an_empty_pipe_is_still_named_empty(tmp_path: Path):
    from photogeom.errors import FileFormatError

    with pytest.raises(FileFormatError, match="no header line and no data"):
        read_points(fifo_with(tmp_path, b"", "points.pipe"), "x,y")


def _pairs_files(tmp_path: Path) -> tuple[Path, Path]:
    """The lidar pairs as SOURCE (x,y,z) and TARGET (X,Y,Z, with a '# crs:' line)."""
    ids, source, target = datasets.point_pairs("lidar_wang2014")

    def write(name: str, cols: str, xyz, head: str = "") -> Path:
        rows = "".join(f"{i},{a!r},{b!r},{c!r}\n" for i, (a, b, c) in zip(ids, xyz.tolist()))
        path = tmp_path / name
        path.write_text(f"{head}id,{cols}\n{rows}", encoding="utf-8")
        return path

    return write("scan.csv", "x,y,z", source), write(
        "reference.csv", "X,Y,Z", target, "# crs: EPSG:25832\n"
    )


@pytest.mark.parametrize(
    "command", [["orient", "absolute"], ["transform", "estimate", "similarity3d"]]
)
def test_a_target_pipe_is_read_for_its_crs_line_and_its_points(
    cli, tmp_path, fifo_read_once, command
):
    # orient absolute scan.csv <(cat reference.csv) stopped with "no header line and no data":
    # the '# crs:' line of TARGET was looked for first, which emptied the pipe
    scan, ref = _pairs_files(tmp_path)
    code, from_file, err = cli(*command, scan, ref, "--json")
    assert code == 0, err
    pipe = fifo_read_once(ref.read_bytes(), "reference.pipe")
    code, from_pipe, err = cli(*command, scan, pipe, "--json")
    assert code == 0, err
    a, b = json.loads(from_file), json.loads(from_pipe)
    assert b["crs"] == a["crs"] == "EPSG:25832"
    assert b["parameters"] == a["parameters"] and b["residuals"] == a["residuals"]


def test_orient_relative_reads_both_images_from_one_pipe(cli, tmp_path, fifo_read_once):
    # one MATCHES file holds both images' columns and is read twice (x1,y1 and x2,y2): from
    # a pipe the second read found it empty
    import photogeom as pg

    io = pg.InteriorOrientation(100.0, unit="mm")
    eo1 = pg.ExteriorOrientation(0.0, 0.0, 1000.0, 0.0, 0.0, 0.0)
    eo2 = pg.ExteriorOrientation(400.0, 10.0, 1005.0, *np.radians([1.0, -2.0, 3.0]))
    rng = np.random.default_rng(1)
    g = np.c_[rng.uniform(-300, 700, 12), rng.uniform(-400, 400, 12), rng.uniform(0, 50, 12)]
    a, b = pg.project(g, io, eo1), pg.project(g, io, eo2)
    rows = "".join(
        f"p{i},{r[0]!r},{r[1]!r},{r[2]!r},{r[3]!r}\n" for i, r in enumerate(np.c_[a, b].tolist())
    )
    matches = tmp_path / "m.csv"
    matches.write_text("id,x1,y1,x2,y2\n" + rows, encoding="utf-8")
    code, from_file, err = cli("orient", "relative", matches, "--f", "100", "--json")
    assert code == 0, err
    pipe = fifo_read_once(matches.read_bytes(), "m.pipe")
    code, from_pipe, err = cli("orient", "relative", pipe, "--f", "100", "--json")
    assert code == 0, err
    assert json.loads(from_pipe)["parameters"] == json.loads(from_file)["parameters"]


def test_rpc_project_reads_ground_points_from_a_pipe(cli, tmp_path, fifo_read_once):
    # rpc project looked for the '# crs:' line of its POINTS first, emptying a pipe
    ground = tmp_path / "ground.csv"
    ground.write_text(
        "# crs: EPSG:4979\nid,lon,lat,h\n1,-56.17,-34.90,30\n2,-56.18,-34.91,40\n",
        encoding="utf-8",
    )
    rpc = datasets.path("ikonos")
    code, from_file, err = cli("rpc", "project", rpc, ground)
    assert code == 0, err
    pipe = fifo_read_once(ground.read_bytes(), "ground.pipe")
    code, from_pipe, err = cli("rpc", "project", rpc, pipe)
    assert code == 0, err

    def rows(text: str) -> list[str]:  # the comment line names the input path
        return [line for line in text.splitlines() if not line.startswith("#")]

    assert rows(from_pipe) == rows(from_file) and len(rows(from_file)) == 3
