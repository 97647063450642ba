"""Chains of commands (review 11): the file one command writes is read right by the next."""

from __future__ import annotations

import csv
import io
import os
import threading
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets

FIDUCIALS = datasets.path("lecture_fiducials")  # id,role,x,y,X,Y
TWO_IMAGES = datasets.path("lecture_two_images")  # id,x1,y1,x2,y2
LIDAR = datasets.path("lidar_wang2014")  # id,x,y,z,X,Y,Z


def _table(text: str) -> tuple[list[str], dict[str, list[float]]]:
    """(header, {id: coordinates}) of a point CSV written by photogeom (comments skipped)."""
    rows = list(csv.reader(io.StringIO("".join(
        line for line in text.splitlines(keepends=True) if not line.startswith("#")
    ))))  # fmt: skip
    header, body = rows[0], rows[1:]
    return header, {r[0]: [float(v) for v in r[1:] if v not in ("control", "check")] for r in body}


def _columns(path: Path, names: list[str]) -> dict[str, list[float]]:
    text = Path(path).read_text().splitlines(keepends=True)
    rows = csv.DictReader(io.StringIO("".join(ln for ln in text if not ln.startswith("#"))))
    return {r["id"]: [float(r[c]) for c in names] for r in rows}


# -- transform apply --inverse on the estimate's own file -----------------------------------


@pytest.mark.parametrize(
    "model, data, source, target",
    [
        ("similarity2d", FIDUCIALS, ["x", "y"], ["X", "Y"]),
        ("similarity3d", LIDAR, ["x", "y", "z"], ["X", "Y", "Z"]),
    ],
)
def test_inverse_reads_the_target_columns_of_a_file_with_both(cli, tmp_path, model, data,
                                                               source, target):
    """A file with x,y and X,Y: --inverse used to read x,y (the source coordinates) and map
    them as if they were targets (fiducial 1: (-16.99, -130.00) instead of (113.02, -0.00))."""
    params = tmp_path / "p.json"
    code, _, err = cli("transform", "estimate", model, data, "--output-params", params)
    assert code == 0, err
    code, out, err = cli("transform", "apply", params, data, "--inverse")
    assert code == 0, err
    header, got = _table(out)
    assert header[1 : 1 + len(source)] == source
    observed = _columns(data, source)
    for pid, xyz in observed.items():  # the inverse of the targets is near the sources
        np.testing.assert_allclose(got[pid][: len(source)], xyz, atol=0.2)
    # the forward direction reads the source columns, as before
    code, out, err = cli("transform", "apply", params, data)
    assert code == 0, err
    header, got = _table(out)
    assert header[1 : 1 + len(target)] == target
    for pid, xyz in _columns(data, target).items():
        np.testing.assert_allclose(got[pid][: len(target)], xyz, atol=0.2)


def test_inverse_with_cols_still_reads_the_named_columns(cli, tmp_path):
    params = tmp_path / "p.json"
    code, _, err = cli("transform", "estimate", "similarity2d", FIDUCIALS,
                       "--output-params", params)  # fmt: skip
    assert code == 0, err
    code, out, err = cli("transform", "apply", params, FIDUCIALS, "--inverse", "--cols", "x,y")
    assert code == 0, err
    assert "input" in out and "(x, y)" in out.splitlines()[0]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_recorded_columns_are_found_in_a_pipe(cli, tmp_path):
    """x2,y2 (no usual names) from a pipe: the fallback to the estimate's columns opened the
    input a second time and found it empty ('no coordinate columns found')."""
    params = tmp_path / "p.json"
    code, _, err = cli("transform", "estimate", "projective2d", TWO_IMAGES, "--source-cols",
                       "x2,y2", "--target-cols", "x1,y1", "--output-params", params)  # fmt: skip
    assert code == 0, err
    code, from_file, err = cli("transform", "apply", params, TWO_IMAGES)
    assert code == 0, err
    fifo = tmp_path / "pts.pipe"
    os.mkfifo(fifo)
    data = Path(TWO_IMAGES).read_bytes()
    done = threading.Event()

    def feed() -> None:
        with open(fifo, "wb") as fh:
            fh.write(data)
        while not done.is_set():  # a second opening sees an empty pipe instead of hanging
            with open(fifo, "wb"):
                pass

    threading.Thread(target=feed, daemon=True).start()
    try:
        code, from_pipe, err = cli("transform", "apply", params, fifo)
    finally:
        done.set()
        os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))  # release the feeder
    assert code == 0, err
    assert _table(from_pipe) == _table(from_file)
