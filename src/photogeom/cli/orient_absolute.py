"""Commands of `photogeom orient` (see :mod:`.orient`)."""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    """Add this module's commands to the ``orient`` group."""
