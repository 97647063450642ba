"""Pieces shared by the command groups: option parsing, consoles, JSON text, point files.

One definition of each (``--check-ids``, comma-separated lists, JSON text, point CSV output,
the console width off a terminal) so that the commands of every group behave alike.
"""

from __future__ import annotations

import json
import os
from contextlib import contextmanager
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from .._lazy import LazyModule
from ..errors import InputError

np = LazyModule("numpy")  # imported when a command needs it: quick start-up


class AngleUnit(str, Enum):
    """Angle units at the command line."""

    deg = "deg"
    gon = "gon"
    rad = "rad"
    arcsec = "arcsec"


#: ``--id-col``, the same in every command that reads point files.
IdColOpt = Annotated[str | None, typer.Option(help="Id column.")]
#: ``--json`` of the commands whose JSON output needs no further words.
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON.")]
#: ``--report`` of the commands that write one HTML report.
ReportOpt = Annotated[Path | None, typer.Option(help="Write an HTML report here.")]
#: Significance level of the data-snooping tests when ``--alpha`` is not given: Baarda's
#: 0.001 (critical w 3.29), the library's default (``photogeom.report.format.SNOOPING_ALPHA``).
DEFAULT_ALPHA = 0.001


def alpha_help(
    test: str,
    upper: float = 1.0,
    uses: str = "the residual table, --json (snooping) and --report flag at it",
) -> str:
    """Help text of ``--alpha``, the same words in every command that has it.

    Parameters
    ----------
    test : str
        The test the level applies to, as the command runs it (``"w-test and tau-test"``).
    upper : float
        Upper bound of the level (unitless; exclusive).
    uses : str
        What the command does at the level.

    Returns
    -------
    str
    """
    return (
        f"Significance level of each {test}, in (0, {upper:g}) [default: {DEFAULT_ALPHA:g}: "
        f"critical w 3.29]; {uses}."
    )


#: ``--alpha`` of the estimating commands whose residual tables show Baarda's w-test and
#: Pope's tau-test (None: not given, :data:`DEFAULT_ALPHA`).
AlphaOpt = Annotated[
    float | None,
    typer.Option("--alpha", help=alpha_help("w-test and tau-test"), show_default=False),
]


def check_alpha(alpha: float | None, *, upper: float = 1.0, off: str | None = None) -> float:
    """The level of ``--alpha`` (:data:`DEFAULT_ALPHA` when not given), checked before any file
    is read.

    Parameters
    ----------
    alpha : float or None
        The value given (None: the option was left out).
    upper : float
        Exclusive upper bound (``bundle adjust``: 0.5, that of ``BundleOptions.alpha``).
    off : str, optional
        When the command runs no test: the words saying why and what to do, e.g. ``"is off
        without --snooping: add --snooping or leave --alpha out"``. A level given then is
        refused, not silently ignored.

    Returns
    -------
    float
        The level to test at (unitless).

    Raises
    ------
    InputError
        ``--alpha`` outside (0, upper) or NaN; given while ``off``.
    """
    if alpha is None:
        return DEFAULT_ALPHA
    if off is not None:
        raise InputError(f"--alpha {alpha:g} sets the level of the data-snooping test, which {off}")
    if not 0 < alpha < upper:
        raise InputError(f"--alpha must be in (0, {upper:g}), got {alpha}")
    return float(alpha)


def with_alpha(fit, alpha: float):
    """``fit`` whose residual tables, ``to_dict()["snooping"]`` and reports test at ``alpha``:
    the level recorded in ``extras["alpha"]`` (read by
    :func:`photogeom.report.format.snooping_alpha`), for estimators without an ``alpha``.

    Parameters
    ----------
    fit : Fit
    alpha : float
        Significance level (unitless), already checked by :func:`check_alpha`.

    Returns
    -------
    Fit
        A copy; ``fit`` is unchanged.
    """
    from dataclasses import replace

    return replace(fit, extras={**dict(fit.extras or {}), "alpha": float(alpha)})


def dash_is_stdout(value: Path | None) -> Path | None:
    """``-o -``: the standard output, as when ``-o`` is left out (None), for the options whose
    default is to print; any other path unchanged."""
    return None if value is not None and str(value) == STDOUT_DASH else value


#: The name that means the standard output on a command line.
STDOUT_DASH = "-"


def refuse_stdout_dash(
    option: str, path: Path | None, *, folder: bool = False, seekable: bool = False
) -> None:
    """Refuse ``-`` for an output that is always written to disk (a report, a parameter
    file, a block folder): a file or folder named ``-`` in the current folder is not what a
    command line means by it, the standard output.

    ``folder``: the output is a folder; ``seekable``: a file written with seeks (a LAS/LAZ
    cloud), which ``/dev/stdout`` cannot take either.

    Raises
    ------
    InputError
        Naming ``option`` and what to give instead.
    """
    if path is None or str(path) != STDOUT_DASH:
        return
    if folder:
        what = "a folder, not to the standard output; give a folder name"
    elif seekable:
        what = "a file, not to the standard output; give a file name"
    else:
        what = "a file, not to the standard output; give a file name (/dev/stdout prints its text)"
    raise InputError(f"{option} -: this output is written to {what}")

#: ``--output/-o`` of the commands that write a point CSV (or print it).
OutputCsvOpt = Annotated[
    Path | None,
    typer.Option(
        "--output", "-o", help="Output CSV (default, or -: stdout).", callback=dash_is_stdout
    ),
]


#: Exit code of a command stopped by SIGTERM (128 + 15, as a shell reports it).
SIGTERM_EXIT = 143


@contextmanager
def sigterm_stops():
    """A scope in which SIGTERM ends the command as Ctrl-C does: an exception
    (``SystemExit(143)``) that runs the clean-up of the running job (``grid correct-images``
    removes the empty folders it made, the temporary files of its images), not an immediate
    death that leaves them. Outside the main thread (no signal handlers there) nothing
    changes.

    Yields
    ------
    None
        The scope is the ``with`` block; the former handler is restored at its end.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum, frame):
        raise SystemExit(SIGTERM_EXIT)

    former = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, former)


def print_id_table(out, table) -> None:
    """Print a table whose first column holds image ids, none of them cut to
    ``DSC00100.…``: the ids are what ``--exclude`` and the image files take. In a pipe or a
    file (no terminal width to keep) the table gets the width it needs; on a terminal too
    narrow for it an id folds onto more lines, whole.

    Parameters
    ----------
    out : rich.console.Console
        Where to print.
    table : rich.table.Table
        The table; its first column is set to fold.
    """
    table.columns[0].overflow = "fold"
    if not out.is_terminal:
        wide = out.options.update_width(10_000)  # measured without the console's width
        out.width = max(out.width, out.measure(table, options=wide).maximum)
    out.print(table)


def console(stderr: bool = False):
    """A console that keeps tables readable when the output is not a terminal."""
    from rich.console import Console

    c = Console(stderr=stderr)
    if not c.is_terminal:
        c = Console(stderr=stderr, width=max(c.width, 110))
    return c


#: Seconds a job runs, with stderr not a terminal (a pipe, a log file), before its first
#: progress line, and seconds between the lines that follow (:class:`LogProgress`).
LOG_PROGRESS_DELAY = 10.0
LOG_PROGRESS_INTERVAL = 30.0


class LogProgress:
    """Progress of a long job as plain lines on stderr, for pipes and log files.

    A job that runs longer than :data:`LOG_PROGRESS_DELAY` seconds gets a line
    ``photogeom: <stage> (<elapsed> s)`` then, and one every :data:`LOG_PROGRESS_INTERVAL`
    seconds, from a background thread (so also while one long step runs), and a last line
    ``photogeom: <stage>: done (<elapsed> s)`` when it ends; shorter jobs print nothing. No
    cursor movement or redrawing: every line stays readable in a log.

    Parameters
    ----------
    text : str
        The stage shown first; :meth:`update` changes it.
    """

    def __init__(self, text: str) -> None:
        import sys
        import threading

        self.text = text
        self._stream = sys.stderr
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._printed = False
        self._t0 = 0.0
        self._thread: threading.Thread | None = None

    def update(self, text: str) -> None:
        """Name the current stage (shown in the next line).

        Parameters
        ----------
        text : str
            The stage, e.g. ``fitting grids: 12 of 250 images``.
        """
        with self._lock:
            self.text = text

    def _line(self, suffix: str = "") -> None:
        import time

        with self._lock:
            text = self.text
            elapsed = time.monotonic() - self._t0
            self._stream.write(f"photogeom: {text}{suffix} ({elapsed:.0f} s)\n")
            self._stream.flush()
            self._printed = True

    def _run(self, delay: float) -> None:
        if delay > 0:
            if self._stop.wait(delay):
                return
            self._line()
        while not self._stop.wait(LOG_PROGRESS_INTERVAL):
            self._line()

    def __enter__(self) -> LogProgress:
        import threading
        import time

        self._t0 = time.monotonic()
        delay = LOG_PROGRESS_DELAY
        if delay <= 0:
            self._line()
        self._thread = threading.Thread(target=self._run, args=(delay,), daemon=True)
        self._thread.start()
        return self

    def __exit__(self, kind, value, tb) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if self._printed and kind is None:
            self._line(": done")

    def start(self) -> None:
        """Start the clock and the lines (as entering the context)."""
        self.__enter__()

    def stop(self) -> None:
        """Stop the lines; a last ``done`` line if any was printed."""
        self.__exit__(None, None, None)


def iteration_progress(max_iterations: int, label: str = "adjusting"):
    """A display of an adjustment's iterations on stderr.

    Returns ``(display, progress)``: the display to enter as a context manager and the
    ``progress(iteration, cost, damping)`` callback of the adjustment. On a terminal a rich
    bar; otherwise (pipes, logs) a :class:`LogProgress` whose lines name the iteration.
    """
    err = console(stderr=True)
    if not err.is_terminal:
        log = LogProgress(label)

        def log_progress(it, cost, lam):
            log.update(f"{label}: iteration {it} of at most {max_iterations}, cost {cost:.6e}")

        return log, log_progress
    from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    prog = Progress(
        SpinnerColumn(),
        TextColumn(f"[bold]{label}[/bold] iteration {{task.completed}}"),
        BarColumn(),
        TextColumn("{task.fields[info]}"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
    )
    task = prog.add_task("adjust", total=max_iterations, info="")

    def progress(it, cost, lam):
        prog.update(
            task, completed=min(it, max_iterations), info=f"cost {cost:.6e}  damping {lam:.1e}"
        )

    return prog, progress


@contextmanager
def stage_spinner(description: str):
    """A spinner with the current stage and the elapsed time on stderr, on a terminal only.

    For long steps whose progress cannot be counted (an adjustment without an iteration
    callback, a grid-size sweep). Yields ``step(text)``, which names the current stage; the
    display is removed when the block ends. In pipes, logs and scripts nothing is drawn: a
    step that runs long gets plain lines instead (:class:`LogProgress`).
    """
    err = console(stderr=True)
    if not err.is_terminal:
        with LogProgress(description) as log:
            yield log.update
        return
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    prog = Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
    )
    with prog:
        task = prog.add_task(description, total=None)
        yield lambda text: prog.update(task, description=text)


def say(text: str, out=None, *, stderr: bool = False) -> None:
    """Print plain text (no markup, no highlighting, no wrapping) to ``out`` or a new console."""
    (out or console(stderr)).print(text, markup=False, highlight=False, soft_wrap=True)


#: Exit code of a batch command that ran every item and some failed (docs/cli.md).
BATCH_FAILED = 1


def batch_failed(message: str) -> None:
    """End a batch command whose items all ran and some failed: ``error: message`` on
    stderr, exit code :data:`BATCH_FAILED` (1; bad input that stops a command before it
    runs anything is exit 2, see :func:`photogeom.cli.main.main`).

    Parameters
    ----------
    message : str
        What failed and what was done, in the words of the command line.

    Raises
    ------
    typer.Exit
        Always, with code 1.
    """
    typer.secho(f"error: {message}", err=True, fg=typer.colors.RED)
    raise typer.Exit(BATCH_FAILED)


def split_names(text: str | None) -> list[str] | None:
    """Comma- (or semicolon-) separated names; None for no or an empty option."""
    if text is None:
        return None
    parts = [p.strip() for p in text.replace(";", ",").split(",") if p.strip()]
    return parts or None


def check_out_cols(names: list[str], n: int, *, role: bool = False) -> None:
    """The ``--out-cols`` names of a point CSV: ``n`` of them, each once, none that of the id
    column (``id``) or, when the output has one (``role``), of the role column. A header
    naming a column twice is refused by every point reader, so such a file could not be read
    back.

    Raises
    ------
    InputError
        Naming ``--out-cols`` and the names to change.
    """
    if len(names) != n:
        raise InputError(f"--out-cols: {len(names)} name(s) for {n} coordinates")
    twice = sorted({c for c in names if names.count(c) > 1})
    if twice:
        raise InputError(
            f"--out-cols: {', '.join(twice)} named more than once; give every coordinate column "
            "its own name"
        )
    others = ["id", "role"] if role else ["id"]
    taken = [c for c in others if c in names]
    if taken:
        raise InputError(
            f"--out-cols: {', '.join(taken)} is already a column of the output "
            f"({', '.join(others)}); give the coordinates other names"
        )


#: A number as typed on the command line (sign, decimals, exponent), and a unit typed
#: after one (``%``, ``°``, ``px``, ``mm``): the patterns of the number messages below.
_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_TYPED_UNIT = r"%|°|[^\W\d_][^\s\d]*"


def image_size_option(text: str, option: str = "--image-size") -> tuple[int, int]:
    """The ``(width, height)`` of an option ``WIDTHxHEIGHT`` (px; ``W,H`` also read)."""
    try:
        w, h = (int(x) for x in text.lower().replace(",", "x").split("x"))
    except ValueError:
        raise InputError(
            f"{option}: expected WIDTHxHEIGHT in pixels, e.g. 7952x5304, not {text!r}"
            + unit_hint(text, option)
        ) from None
    return w, h


class _SizesByRow(dict):
    """``{image id: (width, height)}`` of a CSV of image sizes: the ids as text and, for ids
    of digits only, as integers; an integer that two rows name (``0`` and ``00``) is refused
    when a block with integer ids looks it up, naming both lines (a block with text ids
    matches the texts exactly)."""

    def __init__(self, sizes: dict, twice: dict[int, str]) -> None:
        super().__init__(sizes)
        self.twice = twice  # integer id -> the error naming the two rows

    def _refuse(self, key: object) -> None:
        if type(key) is int and key in self.twice:
            raise InputError(self.twice[key])

    def __contains__(self, key: object) -> bool:
        self._refuse(key)
        return super().__contains__(key)

    def __getitem__(self, key: object) -> tuple[int, int]:
        self._refuse(key)
        return super().__getitem__(key)

    def get(self, key: object, default=None):
        self._refuse(key)
        return super().get(key, default)


def image_sizes_option(
    text: str, option: str = "--image-size"
) -> tuple[int, int] | dict[object, tuple[int, int]]:
    """The images' size of an option: ``WIDTHxHEIGHT`` (px) for every image, or a CSV file
    (a name ending in ``.csv``) of ``image_id,width,height`` rows, one size per image.

    Parameters
    ----------
    text : str
        The option's value.
    option : str
        The option's name, for errors.

    Returns
    -------
    tuple of int, or dict
        ``(width, height)`` px, or ``{image id: (width, height)}``: the ids as text (matched
        exactly) and, for ids of digits only, also as integers (a BAL file's ids, a Bundler
        file's camera indices; ``00`` is image 0). Two rows naming one integer (``0`` and
        ``00``) are refused, naming both lines, when a block with integer ids looks it up.

    Raises
    ------
    InputError
        A value that is neither; a CSV without the three columns, with a size that is not
        two whole numbers > 0, or an id twice (naming the line).
    """
    import csv

    if not text.lower().endswith(".csv"):
        return image_size_option(text, option)
    path = Path(text)
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(
            f"{option} {text}: cannot read it as a CSV of image_id,width,height ({exc})"
        ) from None
    rows = [(k, r) for k, r in enumerate(csv.reader(lines), 1) if r and not r[0].startswith("#")]
    head = [c.strip().lower() for c in rows[0][1]] if rows else []
    if not {"image_id", "width", "height"} <= set(head):
        raise InputError(
            f"{option} {text}: a CSV of image sizes needs the columns image_id,width,height "
            f"(px), one row per image; its header is {','.join(head)[:80]!r}"
        )
    at = [head.index(c) for c in ("image_id", "width", "height")]
    sizes: dict[object, tuple[int, int]] = {}
    as_int: dict[int, tuple[int, str]] = {}  # integer id -> (line, id as typed) of its row
    twice: dict[int, str] = {}
    for k, row in rows[1:]:
        try:
            key, w, h = (row[j].strip() for j in at)
            size = (int(w), int(h))
        except (IndexError, ValueError):
            size = (0, 0)
            key = ""
        if min(size) <= 0 or not key:
            raise InputError(
                f"{option} {text}, line {k}: expected an image id and its width and height "
                f"in whole pixels > 0, got {','.join(row)[:80]!r}"
            )
        if key in sizes:
            raise InputError(f"{option} {text}, line {k}: image {key!r} has a size already")
        sizes[key] = size
        if key.isascii() and key.isdigit():
            n = int(key)
            if n in as_int:
                line, first = as_int[n]
                twice.setdefault(
                    n,
                    f"{option} {text}, lines {line} and {k}: rows {first!r} and {key!r} both "
                    f"name image {n} (the block's image ids are integers); give each image "
                    "one row",
                )
                continue
            as_int[n] = (k, key)
            sizes[n] = size
    return _SizesByRow(sizes, twice)


#: The image-size words of the BAL and Bundler readers (``photogeom.bundle.io_bal.SIZES_FIX``,
#: :func:`photogeom.bundle.io_bal.warn_outside`, ``read_bal``'s mapping) in ``--image-size``'s
#: (``in_cli_words(message, SIZE_WORDS)``; part of :data:`CLI_WORDS`).
SIZE_WORDS: tuple[tuple[str, str], ...] = (
    (
        "(image_size=(width, height) for all, or a mapping image id -> (width, height) for "
        "images of several sizes)",
        "(--image-size WIDTHxHEIGHT for all, or --image-size SIZES.csv, a CSV of "
        "image_id,width,height rows, for images of several sizes)",
    ),
    ("the image size given (image_size)", "the image size given (--image-size)"),
    ("leave image_size out", "leave --image-size out"),
    ("image_size gives no size for image", "--image-size gives no size for image"),
    ("a mapping gives every image's", "a CSV of sizes gives every image's"),
)


def unit_hint(text: str, option: str, unit: str = "px") -> str:
    """The fix for a value of ``option`` (in ``unit``) written with a unit (``100px``,
    ``0.3 px``, ``100,150px``, ``7952x5304px``): the same value without it, else ''.

    Parameters
    ----------
    text : str
        The value as typed.
    option : str
        The option's name, as the user typed it (``--spacing``).
    unit : str
        The unit the option's numbers are in (px).

    Returns
    -------
    str
        ``"; --spacing is in px: give the number alone (--spacing 100)"``, or ``""`` when
        ``text`` has no letters after a number.
    """
    import re

    pieces = re.split(r"(\s*[,;]\s*|(?<=[^\s,;])\s*[xX]\s*(?=\d))", text.strip())
    bare, units = [], set()
    for k, piece in enumerate(pieces):
        if k % 2:  # a separator, kept as typed
            bare.append(piece.strip())
            continue
        m = re.fullmatch(rf"({_NUMBER})\s*([^\W\d_]*)", piece)
        if m is None:
            return ""
        bare.append(m[1])
        if m[2]:
            units.add(m[2])
    if not units:
        return ""
    value = "".join(bare)
    if units == {unit}:
        what = "numbers" if len(pieces) > 1 else "number"
        return f"; {option} is in {unit}: give the {what} alone ({option} {value})"
    said = ", ".join(sorted(units))
    return f"; {option} is in {unit}, not {said}: give it in {unit}, without a unit"


def pixels(option: str):
    """Parser of a float option in pixels: a number, refused with :func:`number_message`'s
    fix when written with a unit (``--spacing 100px``; before: click's "Input should be a
    valid number, unable to parse string as a number").

    Parameters
    ----------
    option : str
        The option's name (``--spacing``).

    Returns
    -------
    callable
        ``str -> float`` for ``typer.Option(parser=...)``.
    """
    return _number_parser(option, "px")


def fraction(option: str):
    """Parser of a float option that is a fraction: a number, refused with the fraction to
    give when written in per cent (``--overlap 60%``: give 0.6; before: click's "Input
    should be a valid number, unable to parse string as a number").

    Parameters
    ----------
    option : str
        The option's name (``--overlap``).

    Returns
    -------
    callable
        ``str -> float`` for ``typer.Option(parser=...)``.
    """
    return _number_parser(option, FRACTION)


def _number_parser(option: str, unit: str):
    """``str -> float`` of a float option in ``unit``; text that is not a number is
    refused with :func:`number_message`'s fix."""

    def parse(text) -> float:
        if isinstance(text, int | float):  # a default value
            return float(text)
        try:
            return float(text)
        except ValueError:
            raise typer.BadParameter(number_message(text, option, unit)) from None

    parse.__name__ = "float"
    return parse


#: The "unit" of an option whose number is a fraction (``--overlap``) or a probability
#: (``--alpha``): written in per cent, it is refused with the fraction to give.
FRACTION = "fraction"

#: The "unit" of a significance level (``--alpha``), a fraction too.
PROBABILITY = "probability"

#: The unit an option's number is in, read off its help text: (pattern, unit), the first
#: match wins. A symbol (px, mm) is compared with the unit typed; a phrase is said as is.
#: An option whose help matches none takes a plain number (a count, a level, a seed).
_HELP_UNITS = (
    (r"\bin \(0, ", PROBABILITY),
    (r"\(fraction\)", FRACTION),
    (r"\[m/px\]", "m/px"),
    (r"\(px[);]|\[px\]|\bin pixels\b|\bin px\b", "px"),
    (r"\bin --unit\b|\(image unit\)", "the unit of --unit"),
    (r"\bimage unit of the cameras\b", "the image unit of the cameras"),
    (r"\bin mm\b", "mm"),
    (r"\((?:in )?m\)|\[m\]", "m"),
    (r"\btarget units\b", "the target coordinates' unit"),
    (r"\bsource units\b", "the source coordinates' unit"),
    (r"\bin sigmas\b", "sigmas"),
    (r"\bnormalised units\b", "normalised units"),
)


_EXAMPLES = {FRACTION: "0.6", PROBABILITY: "0.001"}


def option_unit(help_text: str | None) -> str | None:
    """The unit of a numeric option as its ``--help`` states it.

    Parameters
    ----------
    help_text : str or None
        The option's help.

    Returns
    -------
    str or None
        A unit symbol (``"px"``, ``"mm"``, ``"m"``, ``"m/px"``), :data:`FRACTION`,
        :data:`PROBABILITY`, a phrase
        (``"the unit of --unit"``), or None: a plain number without a unit.
    """
    import re

    for pattern, unit in _HELP_UNITS:
        if re.search(pattern, help_text or ""):
            return unit
    return None


def number_message(text: str, option: str, unit: str | None, *, integer: bool = False) -> str:
    """Why ``text`` is not a value of the numeric ``option``, and what to type instead: a
    number written with a unit (``1mm``, ``0.5px``, ``60%``) or a decimal comma (``0,5``).

    Parameters
    ----------
    text : str
        The value as typed.
    option : str
        The option's name (``--sigma``).
    unit : str or None
        The unit the option is in (:func:`option_unit`): a symbol, :data:`FRACTION`,
        :data:`PROBABILITY`, a phrase, or None (a plain number).
    integer : bool
        The option takes a whole number.

    Returns
    -------
    str
        E.g. ``"'1mm' is not a number; --sigma is in px, not mm: give it in px, without a
        unit"``, ``"'0,5' is not a number; --sigma takes a decimal point: give --sigma 0.5"``.
    """
    import re

    kind = "an integer" if integer else "a number"
    head = f"{text!r} is not {kind}"
    value = text.strip()
    comma = re.fullmatch(r"([+-]?\d+),(\d+)", value)
    if comma:
        if integer:
            return f"{head}; {option} takes a whole number ({option} {comma[1]})"
        return f"{head}; {option} takes a decimal point: give {option} {comma[1]}.{comma[2]}"
    with_unit = re.fullmatch(rf"({_NUMBER})\s*({_TYPED_UNIT})", value)
    if with_unit is None:
        if integer and re.fullmatch(_NUMBER, value):
            return f"{head}; {option} takes a whole number, such as {option} 1"
        if unit in (FRACTION, PROBABILITY):
            return f"{head}; {option} is a {unit}, such as {_EXAMPLES[unit]}"
        said = f" in {unit}" if unit is not None else ""
        return f"{head}; {option} takes a number{said}, such as {option} 1"
    bare, typed = with_unit[1], with_unit[2]
    if unit in (FRACTION, PROBABILITY):
        if typed == "%":
            return f"{head}; {option} is a {unit}: give {float(bare) / 100:g} for {bare} %"
        return f"{head}; {option} is a {unit}, such as {_EXAMPLES[unit]}"
    if unit is None:
        what = "a count" if integer else "a number"
        return f"{head}; {option} is {what} without a unit: give {option} {bare}"
    if " " in unit:  # a phrase: the unit is set elsewhere
        return f"{head}; {option} is in {unit}: give the number alone ({option} {bare})"
    if typed in (unit, f"{unit}s", unit.removesuffix("s")):
        return f"{head}; {option} is in {unit}: give the number alone ({option} {bare})"
    return f"{head}; {option} is in {unit}, not {typed}: give it in {unit}, without a unit"


def _numbers_in_words(param) -> None:
    """Make the numeric option ``param`` refuse a value it cannot read with
    :func:`number_message` (the option's unit from its help) instead of pydantic's "Input
    should be a valid number, unable to parse string as a number"."""
    descriptor = getattr(param, "type_descriptor", None)
    annotation = getattr(descriptor, "annotation", None)
    if annotation not in (int, float) or getattr(param, "_numbers_in_words", False):
        return
    process = param.process_value
    option = max(getattr(param, "opts", None) or [param.name], key=len)
    unit = option_unit(getattr(param, "help", None))
    integer = annotation is int

    def process_value(ctx, value):
        try:
            return process(ctx, value)
        except typer.BadParameter as exc:
            if not isinstance(value, str) or "is not" in exc.message:
                raise  # a parser's own words, or not a typed value
            raise typer.BadParameter(
                number_message(value, option, unit, integer=integer), ctx=ctx, param=param
            ) from None

    param.process_value = process_value
    param._numbers_in_words = True


def numbers_in_words(command) -> None:
    """Give every numeric option of ``command`` and of its sub-commands the messages of
    :func:`number_message` (``--sigma 1mm``: "--sigma is in px, not mm: give it in px,
    without a unit"; ``--sigma 0,5``: "give --sigma 0.5").

    Parameters
    ----------
    command : click command or group
        The command tree built from the application.
    """
    for param in getattr(command, "params", ()):
        _numbers_in_words(param)
    for sub in getattr(command, "commands", {}).values():
        numbers_in_words(sub)


def _units_in_list(parts: list[str], what: str) -> str:
    """The fix for a list of numbers written with units (``--principal-point 1mm,2mm``):
    the numbers alone, else ''."""
    import re

    found = [re.fullmatch(rf"({_NUMBER})\s*({_TYPED_UNIT})?", p) for p in parts]
    if not all(found) or not any(m[2] for m in found):
        return ""
    option = what.split()[0]
    bare = ",".join(m[1] for m in found)
    return (
        f"; give the numbers without a unit ({option} {bare}), in the unit {option}'s help "
        "states"
    )


def split_numbers(
    text: str | None, n: int | None, what: str, *, unit: str | None = None
) -> list[float] | None:
    """Comma-separated finite numbers (exactly ``n`` when given) of the option ``what``.

    ``nan`` and ``inf`` are refused here, by the option's name: no option takes them, and
    the library would name its own argument (``origin_px``, ``lat0``, ``scales``). Numbers
    typed with a unit are refused with the numbers to give: in ``unit`` when given
    (:func:`unit_hint`), else in the unit the option's help states.
    """
    import math

    if text is None:
        return None
    parts = [p.strip() for p in text.replace(";", ",").split(",") if p.strip()]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        hint = unit_hint(text, what.split()[0], unit) if unit else _units_in_list(parts, what)
        raise InputError(f"{what}: expected comma-separated numbers, got {text!r}{hint}") from None
    bad = [p for p, v in zip(parts, vals) if not math.isfinite(v)]
    if bad:
        raise InputError(
            f"{what}: {', '.join(bad)} is not a finite number; give finite numbers ({text!r})"
        )
    if n is not None and len(vals) != n:
        raise InputError(f"{what}: expected {n} comma-separated numbers, got {len(vals)}")
    return vals


def nan_to_none(value):
    """``value`` with every NaN, also inside lists and dicts (statistics of
    what a run did not have: check pairs, stereo models), replaced by None (JSON null)."""
    if isinstance(value, dict):
        return {k: nan_to_none(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [nan_to_none(v) for v in value]
    if isinstance(value, float) and value != value:
        return None
    return value


def json_text(data) -> str:
    """Indented JSON with a final newline (NaN refused).

    The text of ``json.dumps(data, indent=2, allow_nan=False)``; lists of numbers and lists of
    equally long lists of numbers (residuals, one row per point) are encoded by json's C
    encoder in one call and indented by string operations, as the indenting encoder is
    written in Python (1e6 points: most of the time of a --json run).
    """
    try:
        return _indented(data, 0) + "\n"
    except (_Unusual, ValueError, TypeError, RecursionError):
        # what this does not handle, and json's own errors (NaN, a type it cannot encode)
        return json.dumps(data, indent=2, allow_nan=False) + "\n"


class _Unusual(Exception):
    """Data that :func:`_indented` leaves to json itself."""


_SCALARS = (int, float, bool, type(None))


def _numeric_row(value) -> bool:
    return type(value) in (list, tuple) and all(type(v) in _SCALARS for v in value)


def _indented(value, level: int) -> str:
    """``json.dumps(value, indent=2, allow_nan=False)`` at nesting ``level`` (see json_text)."""
    kind = type(value)
    if kind in _SCALARS or kind is str:
        return json.dumps(value, allow_nan=False)
    pad = "\n" + "  " * (level + 1)
    end = "\n" + "  " * level
    if kind is dict:
        if not value:
            return "{}"
        if not all(type(k) is str for k in value):
            raise _Unusual
        items = [json.dumps(k) + ": " + _indented(v, level + 1) for k, v in value.items()]
        return "{" + pad + ("," + pad).join(items) + end + "}"
    if kind not in (list, tuple):
        raise _Unusual
    if not value:
        return "[]"
    if _numeric_row(value):  # numbers: "[1.5, null]" from the C encoder, then indented
        body = json.dumps(value, allow_nan=False)[1:-1]
        return "[" + pad + body.replace(", ", "," + pad) + end + "]"
    width = len(value[0]) if type(value[0]) in (list, tuple) else 0
    if width and all(len(r) == width and _numeric_row(r) for r in value):
        inner = pad + "  "
        body = json.dumps(value, allow_nan=False)[2:-2]
        body = body.replace("], [", "\x00").replace(", ", "," + inner)
        body = body.replace("\x00", pad + "]," + pad + "[" + inner)
        return "[" + pad + "[" + inner + body + pad + "]" + end + "]"
    return "[" + pad + ("," + pad).join(_indented(v, level + 1) for v in value) + end + "]"


def json_id(value):
    """An image or point id as JSON keeps it: its own type (an int stays an int, a text a
    text), numpy scalars as the Python number.

    Parameters
    ----------
    value : int, str or numpy scalar
        The id.

    Returns
    -------
    int, float or str
    """
    return value.item() if hasattr(value, "item") else value


def pair_records(steps: dict | None, **values: dict | None) -> list[dict]:
    """Model pairs as JSON records with typed ids: ``{"image_a": a, "image_b": b, name:
    values[name][(a, b)], ...}``, in the order of ``steps``; a joined text key (``"a-b"``)
    cannot be split back when an id holds ``-``, and loses an int id's type.

    Parameters
    ----------
    steps : dict or None
        ``{(a, b): value}``: the pairs (None or empty: none).
    **values : dict or None
        Further ``{(a, b): value}`` by the record's field name (None: the field left out).

    Returns
    -------
    list of dict
    """
    rows = []
    for a, b in steps or {}:
        row = {"image_a": json_id(a), "image_b": json_id(b)}
        for name, by_pair in values.items():
            if by_pair is not None:
                row[name] = by_pair.get((a, b))
        rows.append(row)
    return rows


def finite_or_none(v) -> float | None:
    """``float(v)``, or None (JSON null) for NaN and infinity."""
    return float(v) if np.isfinite(v) else None


def check_mask(
    ids, default: np.ndarray, check_ids: str | None, *, list_ids: bool = False
) -> np.ndarray:
    """Check points from ``--check-ids`` (overrides ``default``, the role column).

    ``list_ids`` adds the first 30 known ids to the message for an unknown one.
    """
    names = split_names(check_ids)
    if names is None:
        return default
    known = set(ids)
    missing = [i for i in names if i not in known]
    if missing:
        known_ids = ""
        if list_ids:
            known_ids = f"; the ids are {', '.join(ids[:30])}{' ...' if len(ids) > 30 else ''}"
        raise InputError(f"--check-ids: no point with id {', '.join(missing)}{known_ids}")
    return np.isin(np.array(ids, dtype=object), names)


def split_control(ids, ground: np.ndarray, image: np.ndarray, mask: np.ndarray):
    """Control rows (``~mask``) of ground and image, and the ``ids`` / check-point keyword
    arguments of the estimators (``check_ground``, ``check_image``, ``check_ids`` only when
    there are check points)."""
    ctrl = ~mask
    kwargs: dict = {"ids": [i for i, c in zip(ids, ctrl) if c]}
    if mask.any():
        kwargs.update(
            check_ground=ground[mask],
            check_image=image[mask],
            check_ids=[i for i, c in zip(ids, mask) if c],
        )
    return ground[ctrl], image[ctrl], kwargs


def load_pairs(
    source: Path,
    target: Path | None,
    *,
    source_cols: str | None = None,
    target_cols: str | None = None,
    id_col: str | None = None,
    weights_col: str | None = None,
    sigma_col: str | None = None,
    allow_unmatched: bool = False,
):
    """Point pairs (:class:`~photogeom.io.PointPairs`) from one CSV with both coordinate sets
    or from two CSVs joined by id."""
    from ..io import join_points, read_point_pairs, read_points

    if target is None:
        with column_options("--source-cols", source="--source-cols", target="--target-cols"):
            return read_point_pairs(
                source,
                split_names(source_cols),
                split_names(target_cols),
                id_column=id_col,
                weight_column=weights_col,
                sigma_column=sigma_col,
            )
    # An explicit weight/sigma column belongs to the target file; without one, a weight or
    # sigma column found in either file is used (join_points refuses conflicting ones).
    explicit = weights_col is not None or sigma_col is not None
    with column_options("--source-cols"):
        src = read_points(
            source, split_names(source_cols), id_column=id_col, auto_weights=not explicit
        )
    with column_options("--target-cols"):
        dst = read_points(
            target,
            split_names(target_cols),
            id_column=id_col,
            weight_column=weights_col,
            sigma_column=sigma_col,
        )
    try:
        return join_points(src, dst, allow_unmatched=allow_unmatched)
    except InputError as exc:  # the library's keyword as the command's option
        text = str(exc).replace("pass allow_unmatched=True", "give --allow-unmatched")
        raise InputError(text) from None


def check_outputs(inputs: dict[str, Path | None] | None = None, **options: Path | None) -> None:
    """Refuse, before anything is read or computed, output files that cannot be written.

    Parameters
    ----------
    inputs : dict of str to pathlib.Path or None, optional
        The command's input files by argument name (``{"SOURCE": path}``); an output naming
        one of them is refused (the report or the parameters would replace the data they
        were computed from).
    **options : pathlib.Path or None
        Output paths by option name, the underscores of the name read as dashes
        (``report=path`` is ``--report``); None: the option was not given.

    Raises
    ------
    OutputError
        For a path that is a folder or lies in a folder that does not exist; the message
        names the option (``--report: cannot write ...``).
    InputError
        For an output that is one of ``inputs``, naming the option and the argument.
    """
    from .bundle import check_targets

    files = [("--" + k.replace("_", "-"), v) for k, v in options.items()]
    for opt, path in files:
        if path is None or not path.is_file():
            continue
        for arg, given in (inputs or {}).items():
            if given is not None and given.is_file() and os.path.samefile(path, given):
                raise InputError(
                    f"{opt} {path} is the input file {arg}: writing it would replace the data "
                    f"it is computed from; give {opt} another file"
                )
    check_targets(files=files)


def write_outputs(outputs: list[tuple[Path, str]]) -> None:
    """Write every ``(path, text)`` as one: all files are replaced, or none is changed.

    The texts are built in memory first, so a failed computation writes nothing; a file
    that cannot be written raises :class:`~photogeom.errors.OutputError` (one ``error:``
    line, exit code 2, in :func:`photogeom.cli.main.main`) and leaves every destination as
    it was.
    """
    from ..io.atomic import atomic_write_texts

    if outputs:
        atomic_write_texts(outputs)


def emit_points(text: str, output: Path | None, n: int) -> None:
    """A point CSV to stdout, or to ``output`` (atomically) with a note on stderr."""
    from ..io import atomic_write_text

    if output is None:
        typer.echo(text, nl=False)
    else:
        atomic_write_text(output, text)
        say(f"wrote {n} point(s) to {output}", stderr=True)


# --- errors in the words of the command line ----------------------------------------------------

#: Phrases of library messages that name a Python argument, and the command-line option that
#: does the same (the library speaks of its keywords, the command line of its options).
CLI_WORDS: tuple[tuple[str, str], ...] = (
    *SIZE_WORDS,
    ("pass behind='nan' to get NaN", "pass --behind nan to get NaN"),
    ("or pass behind='nan'", "or pass --behind nan"),
    (
        "(angles are radians; the camera looks along its -z axis)",
        "(angles of --eo are in --angle-unit, degrees by default; the camera looks along its "
        "-z axis)",
    ),
    (
        "pass initial= an approximate orientation",
        "pass --initial X0,Y0,Z0,OMEGA,PHI,KAPPA (ground units; angles in --angle-unit) with an "
        "approximate orientation",
    ),
    (
        "degenerate); pass initial=",
        "degenerate); pass start values with --initial X0,Y0,Z0,OMEGA,PHI,KAPPA (ground units; "
        "angles in --angle-unit)",
    ),
    ("(order=1, 2, 3, ...)", "(--order 1, 2, 3, ...)"),
    # --pixel with a camera that does not know where its principal point lies in pixels
    (
        "has no pixel geometry: set origin_px (the pixel position of the image-system origin), "
        "e.g. with InteriorOrientation.digital(...)",
        "has no pixel geometry, which --pixel needs: give the principal point with "
        "--principal-point COL,ROW (px; with --pixel-size for a camera in mm) or a camera in "
        "pixels (--calibration, or a --camera file with origin_px); or leave out --pixel "
        "(image coordinates in the camera's unit)",
    ),
    ("(allow_ballpark=True / --allow-ballpark)", "(--allow-ballpark)"),
    # no command drops weak points: the fix on the command line is the block's files
    (
        "(remove them with Block.drop_weak_points(), or delete their rows from the block's "
        "files)",
        "(delete their rows from the block's files)",
    ),
    (
        "or remove them with Block.drop_weak_points(surveyed=True) or by deleting their rows "
        "from the block's files)",
        "or delete their rows from the block's files)",
    ),
    ("source_system / target_system", "--source-system / --target-system"),
    ("give both source_system and target_system", "give both --source-system and --target-system"),
    (" (photogeom.orientation.p3p lists them)", ""),
    ("(see fit.snooping())", "(see the w-test of the residuals)"),
    (
        "(give the .npz or JSON file that save_grids writes)",
        "(give the grids file that 'photogeom grid fit BLOCK -o grids.npz' writes)",
    ),
    (
        "(try initial= from another source)",
        "(try --initial X0,Y0,Z0,OMEGA,PHI,KAPPA from another source)",
    ),
)


def typed_option(*names: str) -> str:
    """The name of an option with aliases as the running command gives it, for messages.

    Parameters
    ----------
    *names : str
        The option's names, the documented one first (``"--cols", "--ground-cols"``).

    Returns
    -------
    str
        The last of ``names`` given on the command line (``--name VALUE`` or
        ``--name=VALUE``), else the first.
    """
    from ..report.invocation import cli_arguments

    given = [
        a.split("=", 1)[0] for a in cli_arguments() or () if a.split("=", 1)[0] in names
    ]
    return given[-1] if given else names[0]


@contextmanager
def column_options(coordinates: str, **kinds: str):
    """Name the command's options in a 'column(s) ... not found' error of the reads inside.

    Parameters
    ----------
    coordinates : str
        Option choosing the coordinate columns, e.g. ``--image-cols``.
    **kinds : str
        Options for other kinds of column: ``source``, ``target`` (coordinate columns of the
        source and target set of one file), ``weight``, ``sigma``.
    """
    from ..errors import FileFormatError
    from ..io.points import AUTO_COLUMN_HINT, COLUMN_HINT, PAIR_COLUMN_HINT

    try:
        yield
    except FileFormatError as exc:
        kind = getattr(exc, "column_kind", None)
        if PAIR_COLUMN_HINT in str(exc):  # the library's keywords as the two options
            source = kinds.get("source", coordinates)
            target = kinds.get("target", coordinates)
            raise FileFormatError(
                str(exc).replace(
                    PAIR_COLUMN_HINT, f"(or name them, e.g. {source} x2,y2 {target} x1,y1)"
                )
            ) from exc
        if kind is None and AUTO_COLUMN_HINT in str(exc):  # no known column names at all
            raise FileFormatError(
                str(exc).replace(AUTO_COLUMN_HINT, f"(or name them with {coordinates})")
            ) from exc
        if kind is None or COLUMN_HINT not in str(exc):
            raise
        options = {
            "coordinate": coordinates,
            "source coordinate": kinds.get("source", coordinates),
            "target coordinate": kinds.get("target", coordinates),
            "weight": kinds.get("weight", "--weights-col"),
            "sigma": kinds.get("sigma", "--sigma-col"),
        }
        option = options.get(kind, coordinates)
        new = FileFormatError(str(exc).replace(COLUMN_HINT, f"choose others with {option}"))
        new.column_kind = kind
        raise new from exc


def in_cli_words(
    message: str, words: tuple[tuple[str, str], ...] | None = None
) -> str:
    """``message`` with the Python argument names of ``words`` (library phrase, option
    phrase; default :data:`CLI_WORDS`) replaced by options, in their order."""
    for api, cli in CLI_WORDS if words is None else words:
        message = message.replace(api, cli)
    return message


def keywords_as_options(message: str, names: dict[str, str]) -> str:
    """``message`` of a library error with the Python keywords of ``names`` written as the
    command's options.

    ``keyword=value`` (``errors_in='both'``) becomes ``option value`` (``--errors-in both``); a
    keyword with an underscore (``sigma0_prior``) is replaced wherever it stands as a word; a
    plain word (``sigma``, ``order``) only where it begins a clause (at the start, after
    ``: ``, ``; ``, ``(``, ``needs `` or ``and ``) and is the subject of a condition (followed
    by ``must``, ``applies``, ``:``, ``>=``, ``<=``, ``>``, ``<`` or ``/``), so that the same
    word in prose ("the image size must ...") stays.

    Parameters
    ----------
    message : str
        The error message.
    names : dict of str to str
        Python keyword -> command-line option, e.g. ``{"sigma0_prior": "--sigma0-prior"}``.
    """
    import re

    for kw, opt in names.items():
        k = re.escape(kw)
        message = re.sub(
            rf"(?<![\w-]){k}=(['\"]?)([^'\"\s,;)]+)\1",
            lambda m, opt=opt: f"{opt} {m.group(2)}",
            message,
        )
        if "_" in kw:
            message = re.sub(rf"(?<![\w-]){k}(?![\w-])", lambda m, opt=opt: opt, message)
        else:
            message = re.sub(
                rf"(^|: |; |\(|needs |and ){k}(?=:| must | applies | ?[<>]=? | /)",
                lambda m, opt=opt: m.group(1) + opt,
                message,
            )
    return message


def options_in_errors(**names: str):
    """Decorator of a command: errors of photogeom raised inside name the command's options
    instead of the library's keywords (see :func:`keywords_as_options`), e.g.
    ``@options_in_errors(sigma_target="--sigma-target")`` turns ``sigma_target must be a
    positive number`` into ``--sigma-target must be a positive number``. The command's
    signature is kept (typer reads it through ``functools.wraps``)."""
    import functools

    from ..errors import OutputError, PhotogeomError

    def decorate(command):
        @functools.wraps(command)
        def run(*args, **kwargs):
            try:
                return command(*args, **kwargs)
            except PhotogeomError as exc:
                if not isinstance(exc, OutputError) and exc.args and isinstance(exc.args[0], str):
                    exc.args = (keywords_as_options(exc.args[0], names), *exc.args[1:])
                raise

        return run

    return decorate


# --- coordinate reference systems ---------------------------------------------------------------


#: Help text shared by the CRS options: what they take.
CRS_FORMS = "EPSG code (EPSG:25832), WKT, PROJ string, or enu:LAT,LON,H (a local ENU frame)"


def scheduler_option(text: str) -> tuple:
    """``(kind, value)`` of a ``--scheduler`` value (the library's parse; nothing connects
    here), a form photogeom does not take refused by the option's name (the library's
    message names its keyword ``scheduler``)."""
    from ..distributed import _parse_scheduler

    try:
        return _parse_scheduler(text)
    except InputError as exc:
        msg = str(exc)
        raise InputError("--" + msg if msg.startswith("scheduler ") else msg) from None


def cartesian_crs_option(text: str | None, option: str, *, dim: int = 3, unit: str | None = None):
    """The :class:`~photogeom.crs.CrsInfo` of a CRS option (None when not given), validated by
    PROJ and refused when geographic (pyproj is imported only here, when the option is used)."""
    if text is None:
        return None
    from ..crs import cartesian_crs

    return cartesian_crs(text, what=option, dim=dim, unit=unit or None)


def crs_from_comments(comments) -> str | None:
    """The CRS of a ``# crs: ...`` comment line of a point or block file (None without one)."""
    found = None
    for c in comments:
        t = c.strip().lstrip("#").strip()
        if t.lower().startswith("crs:"):
            found = t[4:].strip() or None
    return found


def recorded_crs(text: str, what: str, *, dim: int = 3, unit: str | None = None, fix=None):
    """:func:`photogeom.crs.cartesian_crs` of a CRS a file records; without pyproj installed
    the record is carried as it is (it is only recorded, and only PROJ can read it)."""
    import importlib.util

    from ..crs import CrsInfo, cartesian_crs, frame_from_text

    if frame_from_text(text) is None and importlib.util.find_spec("pyproj") is None:
        return CrsInfo(text.strip(), text.strip(), "unknown (pyproj not installed)", None, False, 3)
    return cartesian_crs(text, what=what, dim=dim, unit=unit or None, fix=fix)


def file_crs(
    value: str | None, option: str, path: Path | None, *, dim: int = 3, unit: str | None = None
):
    """The :class:`~photogeom.crs.CrsInfo` of a CRS option, else of the ``# crs:`` line of the
    point file ``path`` (None: no file to look at); an option contradicting the file's line
    is refused (the option names the CRS of the coordinates, it does not convert them)."""
    rec = None if path is None else crs_from_comments(leading_comments(path))
    if value is None and rec is None:
        return None
    if value is None:
        return recorded_crs(rec, f"{path} ('# crs:' line)", dim=dim, unit=unit)
    info = cartesian_crs_option(value, option, dim=dim, unit=unit)
    if rec is not None and not same_crs(rec, info.text):
        raise InputError(
            f"{path} records the CRS {rec} ('# crs:' line) but {option} says {value}: "
            f"{option} names the CRS of the coordinates, it does not convert them; convert "
            "them with photogeom crs convert"
        )
    return info


def leading_comments(path: Path, max_lines: int = 1000) -> list[str]:
    """The ``#`` comment lines before the header of a text file (none when it cannot be read:
    the reader of the file reports that)."""
    import io

    from ..io.sources import input_kind, pipe_bytes

    out: list[str] = []
    try:
        if input_kind(path) == "pipe":  # read once and kept: the point reader reads it next
            fh = io.StringIO(pipe_bytes(path, None).decode("utf-8", errors="replace"))
        else:
            fh = open(path, encoding="utf-8", errors="replace")
        with fh:
            for _, line in zip(range(max_lines), fh):
                t = line.strip().lstrip("\ufeff")
                if t.startswith("#"):
                    out.append(t[1:].strip())
                elif t:
                    break
    except OSError:
        return []
    return out


def crs_column_names(text: str, what: str) -> tuple[str, str, str]:
    """Names of the coordinate columns a command writes in the CRS ``text`` (option
    ``what``): ``E, N, U`` in a local frame (``enu:...``), ``lon, lat, h`` in a geographic
    CRS (what ``rpc project`` and ``crs convert`` read back), else ``x, y, z``."""
    from .. import crs as _crs

    if _crs.frame_from_text(text) is not None:
        return ("E", "N", "U")
    if _crs.parse_crs(text, what=what).is_geographic:
        return ("lon", "lat", "h")
    return ("x", "y", "z")


def same_crs(a: str, b: str) -> bool:
    """Whether two CRS texts name the same system (PROJ's equality; local frames by origin)."""
    from ..crs import frame_from_text, parse_crs

    fa, fb = frame_from_text(a), frame_from_text(b)
    if fa is not None or fb is not None:
        return fa == fb
    return parse_crs(a) == parse_crs(b)


def option_or_file_crs(
    value: str | None,
    option: str,
    path: Path,
    *,
    fix: str = "convert them with photogeom crs convert",
) -> str | None:
    """The CRS text of a CRS option, else of the ``# crs:`` line of the point file ``path``.

    The check of :func:`file_crs` for commands that take any CRS (geographic ones too: the
    coordinates are converted by PROJ, not computed with): both texts are validated (PROJ or
    ``enu:LAT,LON,H``) and an option that names another CRS than the file's line is refused.

    Parameters
    ----------
    value : str or None
        The option's text (None: not given).
    option : str
        The option's name for the messages (``"--crs"``).
    path : Path
        The point file whose leading ``# crs:`` line is read.
    fix : str
        What to do about a conflict, in the words of the command.

    Returns
    -------
    str or None
        The option's text (stripped), else the file's line; None when neither is there.

    Raises
    ------
    InputError
        An unknown CRS (naming the option or the file's line), or a conflict.
    """
    from ..crs import frame_from_text, parse_crs

    rec = crs_from_comments(leading_comments(path))
    if rec is not None and frame_from_text(rec) is None:
        parse_crs(rec, what=f"{path} ('# crs:' line)")
    if value is None:
        return rec
    text = value.strip()
    if frame_from_text(text) is None:
        parse_crs(text, what=option)
    if rec is not None and not same_crs(rec, text):
        raise InputError(
            f"{path} records the CRS {rec} ('# crs:' line) but {option} says {value}: "
            f"{option} names the CRS of the coordinates, it does not convert them; {fix}"
        )
    return text


def read_detected_block(path: Path, **options):
    """The block at ``path`` in the format its content shows (:func:`photogeom.bundle.
    read_block` without ``kind``), for commands without a format option: a folder holding a
    COLMAP text and a binary model that differ is refused in words such a command can
    follow."""
    from ..bundle.io_colmap import ColmapModelsDiffer
    from ..bundle.io_formats import read_block

    try:
        return read_block(path, **options)
    except ColmapModelsDiffer as exc:
        raise exc.chosen_by(
            "remove the one not to read, or move it to a folder of its own"
        ) from None
