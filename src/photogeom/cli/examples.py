"""`photogeom examples`: List and run the bundled worked examples."""

from __future__ import annotations

import typer

app = typer.Typer(help="List and run the bundled worked examples.", no_args_is_help=True)
