"""Grids files from pipes: ``load_grids`` checked ``is_file()``, false for a
pipe, so ``photogeom grid apply <(cat grids.npz) obs.csv`` said "no such grids file" and
``grid evaluate --grids`` "does not exist". A pipe is now read once (an NPZ from memory,
recognised by its content), a device is refused."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom.calibration import fit_grids, load_grids, save_grids
from photogeom.errors import FileFormatError

sys.path.insert(0, str(Path(__file__).parent))  # the tests' helper modules
from fifos import fifo_with

needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")


@pytest.fixture
def grids():
    rng = np.random.default_rng(3)
    n = 400
    per_image = {}
    for k in (0, 1):
        uv = rng.uniform([0, 0], [999, 799], size=(n, 2))
        per_image[k] = (uv, 0.5 * np.sin(uv / 300.0) + rng.normal(0, 0.1, size=(n, 2)))
    return fit_grids(per_image, (1000, 800), 250.0, folds=0)


@needs_fifo
@pytest.mark.parametrize("suffix,pipe_name", [(".npz", "g.pipe"), (".json", "g.pipe")])
def test_load_grids_from_a_pipe_equals_the_file(tmp_path: Path, grids, suffix, pipe_name):
    f = tmp_path / f"grids{suffix}"
    save_grids(f, grids)
    want = load_grids(f)
    got = load_grids(fifo_with(tmp_path, f.read_bytes(), pipe_name))  # no .npz suffix
    assert sorted(got) == sorted(want)
    uv = np.array([[10.0, 20.0], [500.0, 400.0]])
    for k in want:
        np.testing.assert_array_equal(got[k].evaluate(uv), want[k].evaluate(uv))


@needs_fifo
def test_grid_apply_reads_the_grids_from_a_pipe(cli, tmp_path: Path, grids):
    f = tmp_path / "grids.npz"
    save_grids(f, grids)
    obs = tmp_path / "obs.csv"
    obs.write_text("image_id,u,v\n0,100,200\n1,300,400\n")
    code, want, err = cli("grid", "apply", f, obs)
    assert code == 0, err
    code, got, err = cli("grid", "apply", fifo_with(tmp_path, f.read_bytes(), "g.npz"), obs)
    assert code == 0, err
    assert got == want


def test_a_device_or_a_folder_is_named(tmp_path: Path):
    with pytest.raises(FileFormatError, match="a folder, not a grids file"):
        load_grids(tmp_path)
    if Path("/dev/null").exists():
        with pytest.raises(FileFormatError, match="/dev/null: it is a device"):
            load_grids("/dev/null")


@needs_fifo
@pytest.mark.parametrize(
    "text",
    [
        b'image_id,u,v,name\n0,100,200,"two\nlines"\n1,300,400,x\n',  # quoted line break
        b"image_id,u,v,name\n0,100,200,x\n1,300,400," + b"y" * 200_000 + b"\n",  # refused
        b"image_id,u,v,name\n0,100,200,caf\xe9\n",  # Latin-1: refused
    ],
    ids=["quoted-line-break", "long-field", "latin-1"],
)
def test_grid_apply_reads_observations_from_a_pipe_once(
    cli, tmp_path: Path, grids, fifo_read_once, text
):
    """The CSV reader of ``grid fit`` / ``grid apply`` read the file whole, then opened it
    again for its line-wise reader (a quoted line break, a long field, text that is not
    UTF-8): on a pipe that second open waited for ever."""
    f = tmp_path / "grids.npz"
    save_grids(f, grids)
    obs = tmp_path / "obs.csv"
    obs.write_bytes(text)
    want = cli("grid", "apply", f, obs)
    fifo = fifo_read_once(text, "obs.pipe")
    got = cli("grid", "apply", f, fifo)
    assert got == (want[0], want[1], want[2].replace(str(obs), str(fifo)))


def test_grid_apply_refuses_a_device(cli, tmp_path: Path, grids):
    if not Path("/dev/null").exists():
        pytest.skip("no /dev/null")
    f = tmp_path / "grids.npz"
    save_grids(f, grids)
    code, _, err = cli("grid", "apply", f, "/dev/null")
    assert code == 2
    assert "/dev/null: it is a device" in err
