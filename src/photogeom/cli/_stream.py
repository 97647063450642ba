"""Point jobs of any size: read a CSV block by block, compute, write block by block.

Used by the commands that treat each point on its own (``rpc project``, ``rpc localize``,
``transform apply``, ``camera project``, ``crs convert``). Memory use is that of one block
whatever the size of the file; the output file appears (atomically) only when every block is
done. On a terminal, a job on a file large enough to take more than about a second shows a
progress bar on standard error; in pipes and logs nothing is drawn, and a job that runs long
prints plain progress lines instead.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from pathlib import Path

#: Files at least this large (bytes) get a progress bar on a terminal (about 250 000 points,
#: over a second for any of the streamed jobs).
PROGRESS_BYTES = 16 << 20


#: Variables that set the thread count of the BLAS under numpy (OpenBLAS, MKL, OpenMP).
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")


def single_threaded_blas() -> bool:
    """Have numpy's BLAS run on one thread in this process; call it before numpy loads.

    A streamed job computes on blocks of some 16 000 points: their matrix products are too
    small for BLAS threads to pay off, and the busy-waiting of those threads takes the cores
    from the threads that read and format the blocks (``rpc project`` on 1e6 points took
    twice the time with them on two cores). Does nothing when numpy is already loaded (the
    setting would not take effect) or when the user set a thread count. Returns whether the
    setting was made.
    """
    if "numpy" in sys.modules or any(v in os.environ for v in BLAS_THREAD_VARIABLES):
        return False
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    os.environ["MKL_NUM_THREADS"] = "1"
    return True


def _in_a_log(stream=None) -> bool:
    """Whether ``stream`` (default stderr) is not a terminal: a pipe, a file, a log."""
    stream = sys.stderr if stream is None else stream
    try:
        return not stream.isatty()
    except (AttributeError, ValueError):
        return True


def _wants_progress(size: int, stream=None) -> bool:
    stream = sys.stderr if stream is None else stream
    try:
        return size >= PROGRESS_BYTES and stream.isatty()
    except (AttributeError, ValueError):
        return False


@contextmanager
def progress_bar(total: int, description: str, *, force: bool | None = None):
    """A callable ``advance(done_bytes)`` drawing a rich progress bar on standard error.

    Drawn only on a terminal and for ``total`` >= :data:`PROGRESS_BYTES` (``force``
    overrides the decision). In pipes and logs a job that runs long gets plain lines
    (:class:`~photogeom.cli._common.LogProgress`: bytes and points done); otherwise
    ``advance`` does nothing.
    """
    show = _wants_progress(total) if force is None else force
    if not show and force is None and _in_a_log():
        from ._common import LogProgress

        with LogProgress(description) as log:
            counted = {"n": 0}

            def advance_log(done: int, n_points: int = 0) -> None:
                counted["n"] += n_points
                log.update(
                    f"{description}: {min(done, total) / 1e6:.1f} of {total / 1e6:.1f} MB, "
                    f"{counted['n']:,} points"
                )

            yield advance_log
        return
    if not show:
        yield lambda done, n_points=0: None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        DownloadColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    progress = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        DownloadColumn(),
        TextColumn("{task.fields[points]} points"),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=False,
    )
    with progress:
        task = progress.add_task(description, total=max(total, 1), points="0")
        counter = {"n": 0}

        def advance(done: int, n_points: int = 0) -> None:
            counter["n"] += n_points
            progress.update(task, completed=min(done, total), points=f"{counter['n']:,}")

        yield advance
        progress.update(task, completed=total)


def run_point_job(
    blocks,
    output: Path | None,
    columns: Sequence[str],
    compute: Callable,
    *,
    extra: Sequence[str] = (),
    comments: Sequence[str] = (),
    description: str = "points",
    keep_roles: bool = False,
) -> int:
    """Stream ``blocks`` (a :class:`~photogeom.io.PointBlocks`) through ``compute`` into a CSV.

    ``compute(block)`` returns ``(coords, extra)``: the output coordinates (n, len(columns))
    and a dict of the ``extra`` columns. With ``keep_roles`` the input's role column, if it
    has one, is written after them. Returns the number of points written. The output goes to
    ``output`` (atomically, replaced only when every block succeeded) or to stdout.
    """
    from ..io import PointWriter

    roles = keep_roles and blocks.has_roles
    if roles:
        extra = [*extra, "role"]
    n = 0
    with progress_bar(blocks.size, description) as advance:
        with PointWriter(output, columns, extra=extra, comments=comments) as writer:
            for block in blocks:
                coords, more = compute(block)
                if roles:
                    more = {**more, "role": block.roles}
                writer.write(block.ids, coords, more)
                n += len(block)
                advance(block.bytes_done, len(block))
    return n


@contextmanager
def busy(description: str, *paths, force: bool | None = None):
    """A spinner with the elapsed time on stderr while a job on big input files runs.

    For jobs whose progress cannot be counted (reading a whole file, then one estimate):
    shown on a terminal when the input files together hold at least
    :data:`PROGRESS_BYTES` (``force`` overrides); in pipes and logs a job that runs long
    gets plain lines instead (:class:`~photogeom.cli._common.LogProgress`). Yields
    ``step(text)``, which names the current stage; removed when the job ends.
    """
    size = 0
    for p in paths:
        try:
            size += Path(p).stat().st_size if p is not None else 0
        except OSError:
            pass
    show = _wants_progress(size) if force is None else force
    if not show and force is None and _in_a_log():
        from ._common import LogProgress

        with LogProgress(description) as log:
            yield log.update
        return
    if not show:
        yield lambda text: None
        return
    from rich.console import Console
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    progress = Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=True,
    )
    with progress:
        task = progress.add_task(description, total=None)
        yield lambda text: progress.update(task, description=text)
