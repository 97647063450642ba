"""`photogeom crs`: coordinates between reference systems.

* ``convert`` - points of a CSV from one CRS to another (any EPSG code, WKT or PROJ string,
  by PROJ), or to/from a local ENU frame at a given origin (``enu``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from ._common import IdColOpt, OutputCsvOpt, emit_points, split_names, split_numbers

app = typer.Typer(
    help="Coordinate reference systems (PROJ through pyproj): x/easting/longitude first.",
    no_args_is_help=True,
)

_GEOCENTRIC = "EPSG:4978"


@app.command("convert")
def convert(
    points: Annotated[Path, typer.Argument(help="CSV of points.")],
    from_crs: Annotated[
        str,
        typer.Option(
            "--from",
            help="CRS of the input (EPSG:4979, WKT, PROJ string) or "
            "'enu' (a local frame at --origin).",
        ),
    ],
    to_crs: Annotated[str, typer.Option("--to", help="CRS of the output, or 'enu'.")],
    origin: Annotated[
        str | None,
        typer.Option(help="ENU origin lat,lon,h (degrees, m; WGS 84) for 'enu'."),
    ] = None,
    cols: Annotated[
        str | None, typer.Option(help="Coordinate columns (x/lon first; default: by name).")
    ] = None,
    out_cols: Annotated[
        str | None, typer.Option(help="Output column names (default: x,y,z or E,N,U).")
    ] = None,
    allow_ballpark: Annotated[
        bool, typer.Option(help="Accept an approximate PROJ datum shift.")
    ] = False,
    output: OutputCsvOpt = None,
    id_col: IdColOpt = None,
) -> None:
    """Convert the points of a CSV between CRSs; geographic coordinates are lon,lat[,h] in
    degrees (x first), a local frame 'enu' is east, north, up in metres at --origin on
    WGS 84 (through geocentric WGS 84, EPSG:4978)."""
    import numpy as np

    from .. import crs as _crs
    from ..io import format_points_csv, read_points

    table = read_points(points, split_names(cols), id_column=id_col, auto_weights=False)
    xyz = table.coords
    src, dst = from_crs.strip(), to_crs.strip()
    enu_in, enu_out = src.lower() == "enu", dst.lower() == "enu"
    if (enu_in or enu_out) and origin is None:
        raise InputError("--origin lat,lon,h is needed for an 'enu' frame")
    frame = None
    if origin is not None:
        lat0, lon0, h0 = split_numbers(origin, 3, "--origin")
        frame = _crs.LocalFrame(lat0, lon0, h0)
    if (enu_in or enu_out) and xyz.shape[1] != 3:
        raise InputError(
            f"{points}: 'enu' needs three coordinate columns, found "
            f"{', '.join(table.columns)}; choose them with --cols"
        )
    if enu_in:
        xyz = frame.to_ecef(xyz)
        src = _GEOCENTRIC
    if enu_out:
        out = (
            xyz
            if src == _GEOCENTRIC
            else _crs.transform_points(xyz, src, _GEOCENTRIC, allow_ballpark=allow_ballpark)
        )
        out = frame.from_ecef(out)
        names = ["E", "N", "U"]
    else:
        out = (
            xyz
            if src == dst
            else _crs.transform_points(xyz, src, dst, allow_ballpark=allow_ballpark)
        )
        names = ["x", "y", "z"][: out.shape[1]]
    names = split_names(out_cols) or names
    if len(names) != out.shape[1]:
        raise InputError(f"--out-cols: {len(names)} name(s) for {out.shape[1]} coordinates")
    comments = [f"{from_crs} -> {to_crs}" + (f" (ENU origin {origin})" if frame else "")]
    extra = {"role": list(table.roles)} if table.roles is not None else None
    text = format_points_csv(table.ids, np.asarray(out), names, extra=extra, comments=comments)
    emit_points(text, output, len(table.ids))
