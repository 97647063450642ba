"""`photogeom examples`: list and run the bundled worked examples."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError, PhotogeomError
from ._common import batch_failed, console, say

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
    (atomically, after all examples have run). An example that fails (a damaged bundled
    file, ...) is reported as failed, in the output and the report, and the others still
    run; the command then ends with an error naming the failed examples (exit 1, as every
    batch command with failed items; exit 2 is bad input, nothing run).
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
        from ._common import check_outputs

        # before any example runs (--all takes half a minute): a folder, or a file in a
        # folder that does not exist
        check_outputs(report=report)

    out = console()
    timings: list[tuple[str, float, str]] = []
    failures: list[tuple[str, str]] = []
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
            mark = len(rep) if rep is not None else 0
            if rep is not None:
                rep.add_heading(ex.title, f"photogeom examples run {ex.name}")
            t0 = time.perf_counter()
            try:
                text = ex.run(rep)
                error = None
            except Exception as exc:  # one failed example does not stop the others
                error = _error_text(exc)
            dt = time.perf_counter() - t0
            timings.append((ex.name, dt, "ok" if error is None else "FAILED"))
            progress.console.print(Rule(f"{ex.name}: {ex.title}", align="left", style="blue"))
            if error is None:
                progress.console.print(text, markup=False, highlight=False, soft_wrap=True)
            else:
                failures.append((ex.name, error))
                progress.console.print(
                    f"FAILED: {error}", markup=False, highlight=False, soft_wrap=True
                )
                if rep is not None:
                    rep.truncate(mark)  # none of the failed example's sections half-way
                    rep.add_heading(ex.title, f"photogeom examples run {ex.name}")
                    rep.add_text(f"{ex.name} failed", error, pre=False)
            progress.console.print()
            progress.advance(task)

    summary = Table(title="Examples run", box=box.SIMPLE_HEAD, title_justify="left")
    summary.add_column("example", style="bold")
    summary.add_column("result")
    summary.add_column("time", justify="right")
    for name, dt, result in timings:
        summary.add_row(name, result, f"{dt:.2f} s")
    out.print(summary)
    if rep is not None:
        path = rep.write(report)
        say(f"wrote {path}", out)
    if failures:
        if len(failures) == 1:
            what = f"example {failures[0][0]} failed: {failures[0][1]}"
        else:
            listed = "; ".join(f"{name} ({error})" for name, error in failures)
            what = f"{len(failures)} of {len(chosen)} examples failed: {listed}"
        others = len(chosen) - len(failures)
        if others:
            what += f" (the other {others} ran" + (", see the report)" if rep else ")")
        batch_failed(what)


def _error_text(exc: Exception) -> str:
    """The message of an example's error: photogeom's own as it is (it names the file and
    the fix), any other with its type."""
    if isinstance(exc, PhotogeomError):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"
