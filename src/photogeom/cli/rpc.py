"""`photogeom rpc`: Rational polynomial (RPC) satellite camera models."""

from __future__ import annotations

import typer

app = typer.Typer(help="Rational polynomial (RPC) satellite camera models.", no_args_is_help=True)
