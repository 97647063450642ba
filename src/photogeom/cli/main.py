"""Entry point of the ``photogeom`` command.

Each part registers its command group from its own module; this file only wires them.
"""

from __future__ import annotations

import errno
import os
import re
import sys
from pathlib import Path
from typing import Annotated

import typer
from typer.core import TyperGroup

from ..errors import PhotogeomError
from ._common import numbers_in_words


class _Group(TyperGroup):
    """The ``photogeom`` command: every numeric option of its commands refuses a number
    typed with a unit or a decimal comma in its own words (:func:`numbers_in_words`)."""

    def __init__(self, **attrs) -> None:
        super().__init__(**attrs)
        numbers_in_words(self)


app = typer.Typer(
    cls=_Group,
    name="photogeom",
    help="Analytical photogrammetry with least-squares statistics. "
    "Angles are labelled with their unit; residuals are computed minus observed.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    # plain help text: flags shown as flags, and no rich import before a command needs it
    rich_markup_mode=None,
)


def _version(value: bool) -> None:
    if value:
        from .. import __version__

        typer.echo(f"photogeom {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    ctx: typer.Context,
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            callback=_version,
            is_eager=True,
            help="Print the version and exit.",
        ),
    ] = False,
) -> None:
    """Analytical photogrammetry with least-squares statistics.

    Angles are labelled with their unit; residuals are computed minus observed. Each command
    has --help; shell completion: photogeom --install-completion.
    """
    from .._pipe_scope import pipe_reads  # not ..io: numpy loads after the BLAS setting

    # a command may read a pipe given as input more than once (its format, then its
    # content): each pipe is read once and its bytes are kept until the command ends
    ctx.with_resource(pipe_reads())


_GROUPS = (
    # (module under photogeom.cli, command name)
    ("transform", "transform"),
    ("orient", "orient"),
    ("camera", "camera"),
    ("rpc", "rpc"),
    ("grid", "grid"),
    ("bundle", "bundle"),
    ("cloud", "cloud"),
    ("crs", "crs"),
    ("examples", "examples"),
)


def _register() -> None:
    import importlib

    for module, name in _GROUPS:
        mod = importlib.import_module(f"{__package__}.{module}")
        app.add_typer(mod.app, name=name)


_register()


#: A missing input named ``-`` in an error: ``-: no such file``, ``cannot read -: no such
#: file``, ``no file or folder -`` (the readers' words differ).
_DASH_MISSING = re.compile(r"(?<![^\s(])-(?=[:\s,;)]|$)")


def _dash_input_hint(message: str, argv: list[str]) -> str:
    """What ``-`` means, when ``message`` says that an input ``-`` does not exist and
    ``-`` was given on the command line (no file of that name): ``-`` is the standard
    output, and only for outputs; the standard input is read as ``/dev/stdin``."""
    if "-" not in argv or os.path.lexists("-"):
        return ""
    if not ("no such" in message or "no file" in message) or not _DASH_MISSING.search(message):
        return ""
    return (
        "; '-' stands for the standard output, and only where a command writes (-o -): "
        "to read the standard input, give /dev/stdin"
    )


def main(argv: list[str] | None = None) -> None:
    """Run the CLI; photogeom errors, running out of memory and a standard output that
    cannot be written (a full disk, a file-size limit) become a one-line message and exit
    code 2.

    Usage errors, ``--help`` and the help shown without arguments are handled by click
    (standalone mode), so they print the usual usage text and exit codes.
    """
    import warnings
    from functools import partial

    shown = warnings.showwarning
    numeric = NumericWarnings()
    warnings.showwarning = partial(_show_warning, shown, numeric)
    failed = True
    from ..report.invocation import command_line

    try:
        # the reports a command writes show the command line (their inputs and options)
        with command_line(sys.argv[1:] if argv is None else argv):
            app(args=argv, prog_name="photogeom")
        failed = False
    except SystemExit as exc:  # click's standalone mode ends every run with SystemExit
        failed = exc.code not in (0, None)
        raise
    except PhotogeomError as exc:
        from ._common import in_cli_words

        message = in_cli_words(str(exc))
        message += _dash_input_hint(message, sys.argv[1:] if argv is None else argv)
        typer.secho(f"error: {message}", err=True, fg=typer.colors.RED)
        sys.exit(2)
    except MemoryError as exc:  # numpy's _ArrayMemoryError too: one line, not a traceback
        detail = f" ({exc})" if str(exc) else ""
        typer.secho(
            f"error: not enough memory for this job{detail}; give less input at once or "
            "options that need less (see the command's --help)",
            err=True,
            fg=typer.colors.RED,
        )
        sys.exit(2)
    except OSError as exc:
        if not _standard_output_full(exc):
            raise
        from ..atomicfile import _failure

        reason = str(_failure(Path("-"), exc)).removeprefix("cannot write -: ")
        _quiet_stdout()
        typer.secho(
            f"error: cannot write the standard output: {reason}", err=True, fg=typer.colors.RED
        )
        sys.exit(2)
    except KeyboardInterrupt:  # pragma: no cover - interactive
        sys.exit(130)
    finally:
        warnings.showwarning = shown
        if not failed:
            numeric.show()


#: Errors that only a write can raise: without a file name (photogeom names its own files in
#: an OutputError), they come from the standard output (a redirection to a full disk, a
#: file-size limit, /dev/full).
_WRITE_ONLY_ERRNOS = frozenset(
    e for e in (errno.ENOSPC, getattr(errno, "EDQUOT", None), errno.EFBIG) if e is not None
)


def _standard_output_full(exc: OSError) -> bool:
    """``exc`` is a failed write of the standard output (no file name, a write-only errno)."""
    return exc.filename is None and exc.errno in _WRITE_ONLY_ERRNOS


def _quiet_stdout() -> None:
    """Drop what the standard output still holds: it cannot be written, and flushing it at
    exit would print a second error ("Exception ignored ... OSError")."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # not a file (captured, replaced)
        return
    try:
        null = os.open(os.devnull, os.O_WRONLY)
    except OSError:  # pragma: no cover - no /dev/null
        return
    try:
        os.dup2(null, fd)
    finally:
        os.close(null)


class NumericWarnings:
    """numpy's floating-point warnings raised in photogeom's code during one command, held
    for its end (:func:`_show_warning`)."""

    def __init__(self) -> None:
        self.texts: list[str] = []  # each message once, in the order first raised
        self.explained = False  # photogeom warned in its own words, which names the cause

    def add(self, text: str) -> None:
        if text not in self.texts:
            self.texts.append(text)

    def show(self) -> None:
        """One line each on stderr for a command that finished (its results may hold values
        computed from an overflow or a division by zero), unless photogeom explained."""
        if self.explained:
            return
        for text in self.texts:
            typer.secho(
                f"warning: numerical: {text} (check the results for NaN or infinite values)",
                err=True,
                fg=typer.colors.YELLOW,
            )


def _show_warning(
    shown, numeric: NumericWarnings, message, category, filename, lineno, file=None, line=None
) -> None:
    """A warning of photogeom as one line ``warning: ...`` on stderr, in the words of the
    command line (no source file and line of the library, no Python argument names). numpy's
    floating-point warnings (plain ``RuntimeWarning``: overflow, divide by zero, invalid
    value) raised in photogeom's own code are held in ``numeric`` and shown at the end,
    once each, only when the command neither stopped with a named error nor warned in its
    own words (either says what they meant: coordinates that overflow, points behind a
    camera, points that did not converge). Other warnings as ``shown`` (Python's display)
    shows them."""
    if category is RuntimeWarning and _in_photogeom(filename):
        numeric.add(" ".join(str(message).split()))
        return
    if not getattr(category, "__module__", "").startswith("photogeom"):
        shown(message, category, filename, lineno, file, line)
        return
    from ._common import in_cli_words

    text = " ".join(str(message).split())
    typer.secho(f"warning: {in_cli_words(text)}", err=True, fg=typer.colors.YELLOW)
    numeric.explained = True


def _in_photogeom(filename: str) -> bool:
    """The source file ``filename`` belongs to the photogeom package."""
    import os

    from .. import __file__ as package_init

    root = os.path.dirname(os.path.abspath(package_init))
    try:
        return os.path.commonpath([root, os.path.abspath(filename)]) == root
    except ValueError:  # another drive (Windows)
        return False


if __name__ == "__main__":  # pragma: no cover
    main()
