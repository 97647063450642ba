"""`photogeom examples`: list and run the bundled worked examples."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from ._common import console, say

app = typer.Typer(
    help="List and run the bundled worked examples.", no_args_is_help=True, rich_markup_mode=None
)


@app.command("list")
def list_examples() -> None:
    """List the worked examples (name and what each computes)."""
    from rich import box
    from rich.table import Table

    from ..examples import all_examples

    t = Table(box=box.SIMPLE_HEAD)
    t.add_column("name", style="bold", no_wrap=True)
    t.add_column("example")
    for ex in all_examples():
        t.add_row(ex.name, ex.title)
    out = console()
    out.print(t)
    out.print(
        "Run one with 'photogeom examples run NAME', all with 'photogeom examples run --all "
        "--report examples-report.html'.",
        markup=False,
        highlight=False,
    )


@app.command("run")
def run_examples(
    names: Annotated[
        list[str] | None, typer.Argument(help="Names of the examples to run (see 'list').")
    ] = None,
    run_all: Annotated[bool, typer.Option("--all", help="Run every example.")] = False,
    report: Annotated[
        Path | None,
        typer.Option(help="Write one HTML report (tables, residual plots) of all examples run."),
    ] = None,
) -> None:
    """Run worked examples on the bundled published data and print their results.

    Each example compares its numbers with the published ones. With --report, an HTML
    report with parameter and residual tables and residual vector plots is written
    (atomically, after all examples have run).
    """
    from rich import box
    from rich.progress import (
        BarColumn,
        Progress,
        SpinnerColumn,
        TextColumn,
        TimeElapsedColumn,
    )
    from rich.rule import Rule
    from rich.table import Table

    from ..examples import all_examples, get

    if run_all and names:
        raise InputError("give example names or --all, not both")
    if not run_all and not names:
        raise InputError("name the examples to run (see 'photogeom examples list') or use --all")
    chosen = all_examples() if run_all else [get(n) for n in names or []]

    rep = None
    if report is not None:
        from ..report import Report

        rep = Report(
            "photogeom worked examples",
            subtitle="Computed on the bundled published data sets; each example compares "
            "its results with the published numbers.",
        )
        if not report.parent.exists() and str(report.parent):
            raise InputError(f"cannot write {report}: directory {report.parent} does not exist")

    out = console()
    timings: list[tuple[str, float]] = []
    with Progress(
        SpinnerColumn(),
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
        console=out,
        transient=True,
    ) as progress:
        task = progress.add_task("examples", total=len(chosen))
        for ex in chosen:
            progress.update(task, description=ex.name)
            if rep is not None:
                rep.add_heading(ex.title, f"photogeom examples run {ex.name}")
            t0 = time.perf_counter()
            text = ex.run(rep)
            dt = time.perf_counter() - t0
            timings.append((ex.name, dt))
            progress.console.print(Rule(f"{ex.name}: {ex.title}", align="left", style="blue"))
            progress.console.print(text, markup=False, highlight=False, soft_wrap=True)
            progress.console.print()
            progress.advance(task)

    summary = Table(title="Examples run", box=box.SIMPLE_HEAD, title_justify="left")
    summary.add_column("example", style="bold")
    summary.add_column("time", justify="right")
    for name, dt in timings:
        summary.add_row(name, f"{dt:.2f} s")
    out.print(summary)
    if rep is not None:
        path = rep.write(report)
        say(f"wrote {path}", out)
