"""A pipe read through the library is read afresh by each call; only a ``photogeom``
command (a :func:`photogeom.io.sources.pipe_reads` scope) keeps its bytes, and only until it
ends."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np

import photogeom as pg
from photogeom.io import sources


def _fifo(tmp_path: Path) -> Path:
    fifo = tmp_path / "pipe" / "camera.xml"
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    return fifo


def _serve(fifo: Path, data: bytes) -> None:
    """One writer of ``data`` to ``fifo``: it waits for the next reader to open the pipe (a
    program that writes a new calibration to the same named pipe each time)."""

    def feed() -> None:
        with open(fifo, "wb") as fh:
            fh.write(data)

    threading.Thread(target=feed, daemon=True).start()


def _calibration_bytes(tmp_path: Path, f: float) -> bytes:
    cal = pg.MetashapeCalibration(width=6000, height=4000, f=f, cx=1.5, cy=-2.0)
    path = tmp_path / f"cal_{f:.0f}.xml"
    pg.write_calibration(cal, path)
    return path.read_bytes()


def test_a_named_pipe_read_twice_through_the_library_gives_each_writers_content(tmp_path):
    # two writers, one after the other, on the same named pipe: the second read is the
    # second calibration (the bytes of the first were once kept for the whole process and
    # returned again, a silent stale answer)
    first, second = _calibration_bytes(tmp_path, 4000.0), _calibration_bytes(tmp_path, 5000.0)
    fifo = _fifo(tmp_path)
    _serve(fifo, first)
    assert pg.read_calibration(fifo).f == 4000.0
    _serve(fifo, second)
    assert pg.read_calibration(fifo).f == 5000.0
    assert sources.kept_pipes() is None  # nothing kept outside a command


def test_a_scope_keeps_a_pipe_once_and_drops_it_at_its_end(tmp_path):
    data = b"x" * 1000
    fifo = _fifo(tmp_path)
    _serve(fifo, data)
    with sources.pipe_reads():
        with sources.pipe_reads():  # an inner scope is the outer one
            assert sources.pipe_bytes(fifo, None) == data
        assert sources.kept_pipe_bytes(fifo) == data  # read once, kept for the scope
        assert sources.pipe_bytes(fifo, None) == data
    assert sources.kept_pipes() is None
    assert sources.kept_pipe_bytes(fifo) is None
    _serve(fifo, b"second writer")
    assert sources.pipe_bytes(fifo, None) == b"second writer"


def test_a_command_keeps_nothing_after_it_ends(tmp_path):
    from typer.testing import CliRunner

    from photogeom.cli.main import app

    cal = tmp_path / "camera.xml"
    cal.write_bytes(_calibration_bytes(tmp_path, 4000.0))
    fifo = _fifo(tmp_path)
    _serve(fifo, cal.read_bytes())
    out = tmp_path / "camera.json"
    result = CliRunner().invoke(app, ["camera", "convert", str(fifo), str(out)])
    assert result.exit_code == 0, result.output
    assert np.isclose(pg.read_calibration(out).f, 4000.0)
    assert sources.kept_pipes() is None
