"""The command line a report was made by, for the reports of the ``photogeom`` command.

:func:`photogeom.cli.main.main` runs every command inside :func:`command_line`; a
:class:`~photogeom.report.Report` created meanwhile records :func:`cli_command` and shows it
under its title, so that a report handed in names its input files and options. This module
imports nothing heavy: the command line reads it before any command runs.
"""

from __future__ import annotations

import shlex
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

_ARGS: list[str] | None = None


@contextmanager
def command_line(args: Sequence[str]) -> Iterator[None]:
    """Record ``photogeom ARGS`` as the running command while the block runs.

    Parameters
    ----------
    args : sequence of str
        The arguments after the program name, as given.
    """
    global _ARGS
    before = _ARGS
    _ARGS = [str(a) for a in args]
    try:
        yield
    finally:
        _ARGS = before


def cli_command() -> str | None:
    """The running ``photogeom`` command as one shell line, or None outside the command line.

    Returns
    -------
    str or None
        E.g. ``"photogeom transform estimate similarity2d pts.csv --report r.html"``, each
        word quoted for a POSIX shell where needed.
    """
    return None if _ARGS is None else shlex.join(["photogeom", *_ARGS])


def cli_arguments() -> tuple[str, ...] | None:
    """The arguments of the running ``photogeom`` command (after the program name), or None
    outside the command line."""
    return None if _ARGS is None else tuple(_ARGS)
