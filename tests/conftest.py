"""Test-session set-up.

One BLAS thread per test process: the suite runs with ``pytest -n 2`` on two cores, and
multithreaded BLAS in each worker oversubscribes the cores, which makes the many small
least-squares solves of the tests orders of magnitude slower. Set before numpy loads.

Property tests (hypothesis) draw the same examples on every run (profile "repeatable", the
default, no per-example deadline), so that a test run - and CI - gives the same verdict for
the same code whatever the load of the machine. To search for new counter-examples, run
with ``HYPOTHESIS_PROFILE=explore`` (random draws, failures kept in the local example
database).
"""

import os
import threading

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


import pytest  # noqa: E402  (after the thread settings above)
from hypothesis import settings  # noqa: E402

settings.register_profile("repeatable", derandomize=True, database=None, deadline=None)
settings.register_profile("explore", derandomize=False, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


@pytest.fixture
def cli(capsys):
    """Run the ``photogeom`` command in-process: ``cli(*args) -> (exit code, stdout, stderr)``.

    Arguments are passed through ``str`` (paths welcome); the exit code is that of
    ``SystemExit`` (0 when the command returns).
    """
    from photogeom.cli.main import main

    def run(*args) -> tuple[int, str, str]:
        try:
            main([str(a) for a in args])
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        out = capsys.readouterr()
        return code, out.out, out.err

    return run


@pytest.fixture
def terminal_stderr(monkeypatch):
    """Make the CLI's standard-error console a terminal (progress displays show) writing
    into a buffer; returns a function giving the buffer's text. Call it only after checks
    that need stderr not to be a terminal."""
    import io

    from rich.console import Console

    import photogeom.cli._common as cc

    buf = io.StringIO()
    real = cc.console

    def fake(stderr=False):
        if stderr:
            return Console(file=buf, force_terminal=True, width=100)
        return real(stderr)

    def start():
        monkeypatch.setattr(cc, "console", fake)
        return buf

    return start


@pytest.fixture
def fifo_read_once(tmp_path):
    """``make(data, name)``: a named pipe that gives ``data`` to its first reader and an
    empty stream to any later one (a reader that opened it again used to wait for ever for a
    writer; now such a reader fails instead of hanging the test)."""
    stop = threading.Event()

    def make(data: bytes, name: str):
        fifo = tmp_path / name
        os.mkfifo(fifo)

        def feed() -> None:
            with open(fifo, "wb") as fh:
                fh.write(data)
            while not stop.is_set():  # wake any later open of the pipe with an empty stream
                try:
                    os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
                except OSError:  # no reader now
                    pass
                stop.wait(0.005)

        threading.Thread(target=feed, daemon=True).start()
        return fifo

    yield make
    stop.set()


@pytest.fixture
def at_once(monkeypatch):
    """Progress lines in logs (no terminal) from the first item on, then none until the
    end: what a slow job prints, for commands of small test inputs."""
    import photogeom.cli._common as cc

    monkeypatch.setattr(cc, "LOG_PROGRESS_DELAY", 0.0)
    monkeypatch.setattr(cc, "LOG_PROGRESS_INTERVAL", 1e6)
