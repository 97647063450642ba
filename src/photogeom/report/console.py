"""Terminal output of fits: rich tables with units."""

from __future__ import annotations

from collections.abc import Sequence

from rich import box
from rich.console import Console, Group
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from . import format as F


def _parameter_table(title: str, rows) -> Table:
    """Rows (name, value, std. dev., unit) as a table titled ``title``."""
    t = Table(title=title, box=box.SIMPLE_HEAD, title_justify="left", title_style="bold")
    t.add_column("parameter", style="bold", no_wrap=True)
    t.add_column("value", justify="right", no_wrap=True)
    t.add_column("std. dev.", justify="right", no_wrap=True)
    t.add_column("unit", no_wrap=True)
    for row in rows:
        t.add_row(*row)
    return t


class PointTable:
    """A table of one row per point (the residual tables): the first column (ids) left-aligned,
    the others right-aligned, flagged cells bold red, in rich's ``box.SIMPLE_HEAD`` layout.

    Rich's Table measures and pads every cell through its renderables, in time that grows
    faster than the number of rows (10 000 rows of 10 columns: 19 s; ``transform
    estimate`` on 1e5 points: 190 s, almost all of it printing this table). When the table
    fits the width and its ids and column names are printable ASCII (one character, one
    cell), the same lines are written here as plain segments, in time linear in the rows;
    otherwise (wide characters, a narrow terminal) rich's Table draws it as before.

    Parameters
    ----------
    columns : sequence of str
        Column names (the user's text: never read as rich markup).
    rows : sequence of sequence of str
        Cells, one row per point.
    flags : sequence of sequence of bool
        Cells to highlight (a failed test).
    """

    def __init__(self, columns, rows, flags) -> None:
        self.columns = [str(c) for c in columns]
        self.rows = rows
        self.flags = flags
        ncol = len(self.columns)
        texts = [*self.columns, *(r[0] for r in rows)]
        self.simple = all(t.isascii() and t.isprintable() for t in texts) and all(
            len(r) == ncol for r in rows
        )
        self.widths = [max([len(self.columns[j])] + [len(r[j]) for r in rows]) for j in range(ncol)]
        self.width = 2 + sum(w + 2 for w in self.widths) + ncol - 1

    def rich_table(self) -> Table:
        """The table as a rich Table (cells as Text: shown as written)."""
        t = Table(box=box.SIMPLE_HEAD)
        for j, col in enumerate(self.columns):
            t.add_column(Text(col), justify="left" if j == 0 else "right", no_wrap=True)
        for row, flags in zip(self.rows, self.flags):
            t.add_row(*(Text(c, style="bold red" if f else "") for c, f in zip(row, flags)))
        return t

    def _cell(self, j: int, text: str) -> str:
        return text.ljust(self.widths[j]) if j == 0 else text.rjust(self.widths[j])

    def __rich_console__(self, console, options):
        if not self.simple or self.width > options.max_width:
            yield self.rich_table()
            return
        from rich.segment import Segment

        new_line = Segment.line()
        blank = Segment(" " * self.width)
        header = console.get_style("table.header")
        flagged = console.get_style("bold red")
        yield blank
        yield new_line
        yield Segment(" ")
        for j, col in enumerate(self.columns):
            if j:
                yield Segment(" ")
            yield Segment(f" {self._cell(j, col)} ", header)
        yield Segment(" ")
        yield new_line
        yield Segment(" " + "\u2500" * (self.width - 2) + " ")
        yield new_line
        for row, flags in zip(self.rows, self.flags):
            if not any(flags):
                cells = " ".join(f" {self._cell(j, c)} " for j, c in enumerate(row))
                yield Segment(f" {cells} ")
            else:
                # edge or divider, the cell's padding, the text (styled when flagged)
                for j, (c, f) in enumerate(zip(row, flags)):
                    pad = " " * (self.widths[j] - len(c))
                    yield Segment("  " if j == 0 else "  " + pad)
                    yield Segment(c, flagged) if f else Segment(c)
                    yield Segment(pad + " " if j == 0 else " ")
                yield Segment(" ")
            yield new_line
        yield blank
        yield new_line

    def __rich_measure__(self, console, options):
        from rich.measure import Measurement

        if not self.simple:
            return Measurement.get(console, options, self.rich_table())
        return Measurement(self.width, self.width)


def fit_renderable(fit, title: str | None = None, angle_unit: str = "deg") -> Group:
    """Rich renderable of a fit: parameters, statistics, residuals, check points, notes.

    Parameters
    ----------
    fit : Fit
        The estimate.
    title : str, optional
        Title; default the model name and method.
    angle_unit : str, default "deg"
        Unit of the angle parameters.

    Returns
    -------
    rich.console.Group
    """
    title = title or f"{F.model_name(fit)} ({fit.method})"
    items: list = []

    params = _parameter_table("Parameters", F.parameter_rows(fit, angle_unit))

    stats = Table(
        title="Adjustment",
        box=box.SIMPLE_HEAD,
        show_header=False,
        title_justify="left",
        title_style="bold",
    )
    stats.add_column("quantity", style="dim", no_wrap=True)
    stats.add_column("value")
    for label, value in F.statistics_rows(fit):
        stats.add_row(label, value)

    items.append(params)
    tb = F.textbook_rows(fit, angle_unit)
    if tb:
        items.append(_parameter_table("Textbook form", tb))
    hm = F.helmert_rows(fit)
    if hm:
        items.append(_parameter_table(F.HELMERT_TITLE, hm))
    items.append(stats)

    for check in (False, True):
        tab = F.residual_table(fit, check=check)
        if tab is None:
            continue
        heading = (
            f"Check point residuals ({len(tab.rows)}, not in the estimate)"
            if check
            else f"Control point residuals ({len(tab.rows)})"
        )
        items.append(Text(heading, style="bold"))
        items.append(PointTable(tab.columns, tab.rows, tab.flags))
        for line in tab.footer:
            items.append(Text(line, style="dim"))
    for note in fit.notes:
        items.append(Text(f"note: {note}", style="yellow"))
    if not fit.converged:
        items.append(
            Text("The iteration did NOT converge; do not trust these numbers.", style="bold red")
        )
    return Group(Panel(Text(title, style="bold"), box=box.HORIZONTALS, expand=True), *items)


def print_fit(
    fit,
    console: Console | None = None,
    angle_unit: str = "deg",
    title: str | None = None,
) -> None:
    """Print a fit as rich tables.

    Parameters with std. dev. and units, statistics, residuals v = computed - observed,
    check points, notes. Never fails on undefined statistics (e.g. sigma0 when the
    redundancy is 0: shown as "undefined").

    Parameters
    ----------
    fit : Fit
        The estimate.
    console : rich.console.Console, optional
        Where to print; default a new console (standard output).
    angle_unit : str, default "deg"
        Unit of the angle parameters.
    title : str, optional
        Title; default the model name and method.
    """
    console = console or Console()
    console.print(fit_renderable(fit, title=title, angle_unit=angle_unit))


def print_table(
    title: str | None,
    columns: Sequence[str],
    rows: Sequence[Sequence],
    console: Console | None = None,
) -> None:
    """Print a simple table (first column left-aligned, the others right-aligned).

    Cells are shown as they are (text, not rich markup: they hold point ids); column names
    may hold markup.

    Parameters
    ----------
    title : str or None
        Table title.
    columns : sequence of str
        Column headings.
    rows : sequence of sequences
        Cells; floats are formatted, other values shown with ``str``.
    console : rich.console.Console, optional
        Where to print; default a new console (standard output).
    """
    console = console or Console()
    t = Table(title=title, box=box.SIMPLE_HEAD, title_justify="left", title_style="bold")
    for j, c in enumerate(columns):
        # a cell too wide for the console wraps onto a second line, never ends in an
        # ellipsis (a number cut to "-1424.5862…" has lost digits)
        t.add_column(str(c), justify="left" if j == 0 else "right", overflow="fold")
    for r in rows:
        cells = (
            c if isinstance(c, str) else F.fmt_value(c) if isinstance(c, float) else str(c)
            for c in r
        )
        t.add_row(*(Text(c) for c in cells))
    width = console.width
    if not console.is_terminal:  # a file or a pipe: as wide as the table needs
        wide = console.options.update(width=10_000)
        console.width = max(width, console.measure(t, options=wide).maximum)
    try:
        console.print(t)
    finally:
        console.width = width


def fit_text(fit, title: str | None = None, angle_unit: str = "deg", width: int = 110) -> str:
    """The :func:`print_fit` output as plain text (no colour codes).

    Parameters
    ----------
    fit : Fit
        The estimate.
    title : str, optional
        Title; default the model name and method.
    angle_unit : str, default "deg"
        Unit of the angle parameters.
    width : int, default 110
        Line width, characters.

    Returns
    -------
    str
    """
    console = Console(
        width=width, record=True, color_system=None, force_terminal=False, file=_Null()
    )
    console.print(fit_renderable(fit, title=title, angle_unit=angle_unit))
    return console.export_text()


class _Null:
    def write(self, s):  # pragma: no cover - trivial
        return len(s)

    def flush(self):  # pragma: no cover - trivial
        pass
