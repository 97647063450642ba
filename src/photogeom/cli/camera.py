"""`photogeom camera`: Frame camera models: projection, DLT."""

from __future__ import annotations

import typer

app = typer.Typer(help="Frame camera models: projection, DLT.", no_args_is_help=True)
