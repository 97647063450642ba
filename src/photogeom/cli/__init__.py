"""The ``photogeom`` command line (typer + rich)."""
