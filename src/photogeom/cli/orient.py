"""`photogeom orient`: absolute orientation, space resection and intersection.

The commands live in :mod:`.orient_absolute` and :mod:`.orient_camera`; each module has a
``register(app)`` function that adds its commands to this group.
"""

from __future__ import annotations

import typer

from . import orient_absolute, orient_camera, orient_relative

app = typer.Typer(
    help="Orientations: absolute (3D similarity), resection, intersection, relative.",
    no_args_is_help=True,
)
orient_absolute.register(app)
orient_camera.register(app)
orient_relative.register(app)
