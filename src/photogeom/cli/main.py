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
    ("examples", "examples"),
)


def _register() -> None:
    import importlib

    for module, name in _GROUPS:
        mod = importlib.import_module(f"{__package__}.{module}")
        app.add_typer(mod.app, name=name)


_register()


def main() -> None:
    """Run the CLI; photogeom errors become a one-line message and exit code 2."""
    try:
        app(standalone_mode=False)
    except PhotogeomError as exc:
        typer.secho(f"error: {exc}", err=True, fg=typer.colors.RED)
        sys.exit(2)
    except (typer.Abort, KeyboardInterrupt):
        sys.exit(130)
    except typer.Exit as exc:  # pragma: no cover - typer's normal exit
        sys.exit(exc.exit_code)
    except Exception as exc:  # click usage errors
        import click

        if isinstance(exc, click.ClickException):
            exc.show()
            sys.exit(exc.exit_code)
        raise


if __name__ == "__main__":  # pragma: no cover
    main()
