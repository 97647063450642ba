"""Entry point of the ``photogeom`` command.

Each part registers its command group from its own module; this file only wires them.
"""

from __future__ import annotations

import sys

import typer

from ..errors import PhotogeomError

app = typer.Typer(
    name="photogeom",
    help="Analytical photogrammetry with least-squares statistics. "
    "Angles are labelled with their unit; residuals are computed minus observed.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

_GROUPS = (
    # (module under photogeom.cli, command name)
    ("transform", "transform"),
    ("orient", "orient"),
    ("camera", "camera"),
    ("rpc", "rpc"),
    ("grid", "grid"),
    ("examples", "examples"),
)


def _register() -> None:
    import importlib

    for module, name in _GROUPS:
        mod = importlib.import_module(f"{__package__}.{module}")
        app.add_typer(mod.app, name=name)


_register()


def main(argv: list[str] | None = None) -> None:
    """Run the CLI; photogeom errors become a one-line message and exit code 2.

    Usage errors, ``--help`` and the help shown without arguments are handled by click
    (standalone mode), so they print the usual usage text and exit codes.
    """
    try:
        app(args=argv, prog_name="photogeom")
    except PhotogeomError as exc:
        typer.secho(f"error: {exc}", err=True, fg=typer.colors.RED)
        sys.exit(2)
    except KeyboardInterrupt:  # pragma: no cover - interactive
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    main()
