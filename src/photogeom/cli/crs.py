"""`photogeom crs`: coordinates between reference systems.

* ``convert`` - points of a CSV from one CRS to another (any EPSG code, WKT or PROJ string,
  by PROJ), or to/from a local ENU frame at a given origin (``enu``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from ._common import (
    IdColOpt,
    OutputCsvOpt,
    column_options,
    crs_column_names,
    emit_points,
    option_or_file_crs,
    split_names,
    split_numbers,
)

app = typer.Typer(
    help="Coordinate reference systems (PROJ through pyproj): x/easting/longitude first.",
    no_args_is_help=True,
)


#: Column sets of geographic points tried when POINTS has none of the usual names (the output
#: of 'rpc localize' and of 'crs convert --to' a geographic CRS).
GEOGRAPHIC_COLS = (("lon", "lat", "h"), ("lon", "lat", "height"),
                   ("longitude", "latitude", "height"), ("longitude", "latitude", "h"),
                   ("lon", "lat"), ("longitude", "latitude"))  # fmt: skip


def _read_input(points: Path, cols: str | None, id_col: str | None):
    """The points of POINTS: --cols, else the usual names (x,y,z, E,N,H, ...), else
    lon,lat[,h] (a missing column set names --cols)."""
    from ..errors import FileFormatError
    from ..io import read_points
    from ..io.points import AUTO_COLUMN_HINT

    kw = {"id_column": id_col, "auto_weights": False}
    with column_options("--cols"):
        if cols is not None:
            return read_points(points, split_names(cols), **kw)
        try:
            return read_points(points, None, **kw)
        except FileFormatError as exc:
            if "no coordinate columns found" not in str(exc):
                raise
            first = exc
        for names in GEOGRAPHIC_COLS:
            try:
                return read_points(points, names, **kw)
            except FileFormatError as exc:
                if getattr(exc, "column_kind", None) is None:
                    raise
        sets = " or ".join(",".join(c) for c in GEOGRAPHIC_COLS)
        raise FileFormatError(
            str(first).replace(AUTO_COLUMN_HINT, f"or {sets} {AUTO_COLUMN_HINT}")
        ) from None


@app.command("convert")
def convert(
    points: Annotated[Path, typer.Argument(help="CSV of points.")],
    to_crs: Annotated[str, typer.Option("--to", help="CRS of the output, 'enu' or enu:LAT,LON,H.")],
    from_crs: Annotated[
        str | None,
        typer.Option(
            "--from",
            help="CRS of the input (EPSG:4979, WKT, PROJ string), 'enu' (a local frame at "
            "--origin) or enu:LAT,LON,H. Default: the '# crs:' line of POINTS; a --from "
            "naming another CRS than that line is refused.",
            show_default=False,
        ),
    ] = None,
    origin: Annotated[
        str | None,
        typer.Option(help="ENU origin lat,lon,h (degrees, m; WGS 84) for 'enu'."),
    ] = None,
    cols: Annotated[
        str | None,
        typer.Option(
            help="Coordinate columns (x/lon first; default: by name, x,y,z, X,Y,Z, E,N,H, ... "
            "or lon,lat,h)."
        ),
    ] = None,
    out_cols: Annotated[
        str | None,
        typer.Option(
            help="Output column names (default: x,y,z; lon,lat,h for a geographic --to; E,N,U "
            "for 'enu')."
        ),
    ] = None,
    allow_ballpark: Annotated[
        bool, typer.Option(help="Accept an approximate PROJ datum shift.")
    ] = False,
    output: OutputCsvOpt = None,
    id_col: IdColOpt = None,
) -> None:
    """Convert the points of a CSV between CRSs; geographic coordinates are lon,lat[,h] in
    degrees (x first), a local frame 'enu' is east, north, up in metres at --origin on
    WGS 84 (through geocentric WGS 84, EPSG:4978). The CRS of the input is --from or the
    '# crs:' line of POINTS (a --from contradicting the line is refused). The output records
    its CRS in a '# crs: ...' line (enu:LAT,LON,H for a local frame), which the other
    commands read."""
    import numpy as np

    from .. import crs as _crs
    from ..io import format_points_csv

    table = _read_input(points, cols, id_col)
    xyz = table.coords
    frame = None
    if origin is not None:
        lat0, lon0, h0 = split_numbers(origin, 3, "--origin")
        frame = _crs.LocalFrame(lat0, lon0, h0)

    def resolve(text: str, option: str) -> str:
        t = text.strip()
        if t.lower() == "enu":
            if frame is None:
                raise InputError("--origin lat,lon,h is needed for an 'enu' frame")
            return frame.to_text()
        if _crs.frame_from_text(t) is None:
            _crs.parse_crs(t, what=option)
        return t

    src = option_or_file_crs(
        None if from_crs is None else resolve(from_crs, "--from"),
        "--from",
        points,
        fix="leave --from out (the file's line is the default) or correct the line",
    )
    if src is None:
        raise InputError(
            f"{points} records no CRS (no '# crs:' line): give the CRS of its coordinates "
            "with --from (e.g. --from EPSG:4979)"
        )
    dst = resolve(to_crs, "--to")
    enu_in = _crs.frame_from_text(src) is not None
    enu_out = _crs.frame_from_text(dst) is not None
    if (enu_in or enu_out) and xyz.shape[1] != 3:
        raise InputError(
            f"{points}: 'enu' needs three coordinate columns, found "
            f"{', '.join(table.columns)}; choose them with --cols"
        )
    if not enu_in:
        _check_geographic(table, src, points)
    if enu_in or enu_out:
        out = _crs.points_between(xyz, src, dst, allow_ballpark=allow_ballpark)
    elif src == dst:
        out = xyz
    else:
        out = _crs.transform_points(xyz, src, dst, allow_ballpark=allow_ballpark)
    names = split_names(out_cols) or list(crs_column_names(dst, "--to")[: out.shape[1]])
    if len(names) != out.shape[1]:
        raise InputError(f"--out-cols: {len(names)} name(s) for {out.shape[1]} coordinates")
    comments = [f"{src} -> {to_crs}" + (f" (ENU origin {origin})" if frame else "")]
    comments.append(f"crs: {dst}")
    extra = {"role": list(table.roles)} if table.roles is not None else None
    text = format_points_csv(table.ids, np.asarray(out), names, extra=extra, comments=comments)
    emit_points(text, output, len(table.ids))


def _check_geographic(table, src: str, points: Path) -> None:
    """Refuse, by point id, latitudes outside [-90, 90] degrees and longitudes outside
    [-360, 360] degrees when the input CRS ``src`` is geographic (PROJ would stop with
    "Invalid latitude" and no point named): most often projected or local coordinates given
    a geographic --from, or columns in the wrong order."""
    import numpy as np

    from .. import crs as _crs

    c = _crs.parse_crs(src, what="--from")
    geographic = c.is_geographic or (
        c.is_compound and bool(c.sub_crs_list) and c.sub_crs_list[0].is_geographic
    )
    if not geographic or table.coords.shape[1] < 2:
        return
    lon, lat = table.coords[:, 0], table.coords[:, 1]
    bad = np.flatnonzero(~((np.abs(lat) <= 90.0) & (np.abs(lon) <= 360.0)))
    if bad.size == 0:
        return
    shown = ", ".join(
        f"{table.ids[i]} (lon {lon[i]:g}, lat {lat[i]:g})" for i in bad[:5]
    ) + (" ..." if bad.size > 5 else "")
    cols = ",".join(table.columns)
    raise InputError(
        f"{points}: {bad.size} point(s) are not longitude, latitude in degrees ({cols} read as "
        f"lon,lat in {src}): {shown}; if they are projected or local coordinates, give their "
        "CRS with --from (or the file's '# crs:' line); if the columns are in another order, "
        "choose them with --cols LON,LAT[,H]"
    )
