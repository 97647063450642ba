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


def fit_renderable(fit, title: str | None = None, angle_unit: str = "deg") -> Group:
    """Rich renderable of a fit: parameters, statistics, residuals, check points, notes."""
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
        # point ids and column names are the user's text: Text objects, never rich markup
        # or emoji codes (an id "P[/x]" stopped the summary with a MarkupError)
        t = Table(box=box.SIMPLE_HEAD)
        for j, col in enumerate(tab.columns):
            t.add_column(Text(col), justify="left" if j == 0 else "right", no_wrap=True)
        for row, flags in zip(tab.rows, tab.flags):
            t.add_row(*(Text(c, style="bold red" if f else "") for c, f in zip(row, flags)))
        items.append(t)
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
    """Print a fit as rich tables (parameters with std. dev. and units, statistics,
    residuals v = computed - observed, check points, notes).

    Never fails on undefined statistics (e.g. sigma0 when the redundancy is 0: shown as
    "undefined").
    """
    console = console or Console()
    console.print(fit_renderable(fit, title=title, angle_unit=angle_unit))


def print_table(
    title: str | None,
    columns: Sequence[str],
    rows: Sequence[Sequence],
    console: Console | None = None,
) -> None:
    """Print a simple table (first column left-aligned, the others right-aligned). Cells are
    shown as they are (text, not rich markup: they hold point ids); column names may hold
    markup."""
    console = console or Console()
    t = Table(title=title, box=box.SIMPLE_HEAD, title_justify="left", title_style="bold")
    for j, c in enumerate(columns):
        t.add_column(str(c), justify="left" if j == 0 else "right")
    for r in rows:
        cells = (
            c if isinstance(c, str) else F.fmt_value(c) if isinstance(c, float) else str(c)
            for c in r
        )
        t.add_row(*(Text(c) for c in cells))
    console.print(t)


def fit_text(fit, title: str | None = None, angle_unit: str = "deg", width: int = 110) -> str:
    """The :func:`print_fit` output as plain text (no colour codes)."""
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
