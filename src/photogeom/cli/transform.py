"""`photogeom transform`: Estimate and apply 2D/3D coordinate transformations."""

from __future__ import annotations

import typer

app = typer.Typer(help="Estimate and apply 2D/3D coordinate transformations.", no_args_is_help=True)
