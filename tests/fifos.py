"""Named pipes for the tests of readers that take their input from a pipe (``<(cat f)``,
``... | photogeom ... /dev/stdin``): a pipe gives its content once, to its first reader."""

from __future__ import annotations

import os
import threading
from pathlib import Path


def fifo_with(tmp_path: Path, data: bytes, name: str) -> Path:
    """A named pipe ``tmp_path / name`` that gives ``data`` to its first reader (a writer
    thread blocks until the reader opens it; a reader that stops early ends it quietly)."""
    fifo = tmp_path / name
    os.mkfifo(fifo)

    def feed() -> None:
        try:
            with open(fifo, "wb") as fh:  # blocks until the reader opens the pipe
                fh.write(data)
        except BrokenPipeError:  # the reader stopped early (e.g. a refused raster)
            pass

    threading.Thread(target=feed, daemon=True).start()
    return fifo

