"""The scope in which each pipe given as input is read once (:func:`pipe_reads`).

Apart from :mod:`photogeom.io.sources`, which reads the pipes, so that the command line can
open the scope for every command without importing the readers (and numpy) first.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

#: The pipes read in the current scope, by (path, device, inode), with the limit they were
#: read to (None: the whole stream): a command may read one input several times (its
#: format, a CRS it records, its content) and a pipe gives its content once. None outside
#: every scope: a pipe is then read by each call and nothing is kept. One for the process,
#: not per thread: the worker threads of a command see the command's scope.
_KEPT: dict[tuple[str, int, int], tuple[bytes, int | None]] | None = None


def kept_pipes() -> dict[tuple[str, int, int], tuple[bytes, int | None]] | None:
    """The pipes kept in the current scope (a dict to add to), or None outside every scope."""
    return _KEPT


@contextmanager
def pipe_reads() -> Iterator[None]:
    """A scope in which each pipe is read once and its bytes are kept for later reads.

    Every command of the ``photogeom`` CLI runs in one such scope, so that a command which
    reads one pipe several times (its format first, then its content) gets the same bytes
    each time; the bytes are dropped when the scope ends. A scope inside a scope is the
    outer one. Outside every scope each read of a pipe reads the stream (what a new writer
    wrote) and keeps nothing, so a long-running program that reads many pipes through the
    library holds none of them.

    Yields
    ------
    None
        The scope is the ``with`` block.

    Examples
    --------
    >>> from photogeom.io.sources import pipe_reads
    >>> with pipe_reads():
    ...     pass  # read a pipe several times here
    """
    global _KEPT
    if _KEPT is not None:
        yield
        return
    _KEPT = {}
    try:
        yield
    finally:
        _KEPT = None
