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
    check_out_cols,
    column_options,
    crs_column_names,
    option_or_file_crs,
    say,
    split_names,
    split_numbers,
    typed_option,
)
from ._stream import run_point_job, single_threaded_blas

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
    """The points of POINTS, opened block by block (:class:`~photogeom.io.PointBlocks`):
    --cols, else the usual names (x,y,z, E,N,H, ...), else lon,lat[,h] (a missing column set
    names --cols)."""
    from ..errors import FileFormatError
    from ..io import PointBlocks
    from ..io.points import AUTO_COLUMN_HINT

    kw = {"id_column": id_col}
    with column_options("--cols"):
        if cols is not None:
            return PointBlocks(points, split_names(cols), **kw)
        try:
            return PointBlocks(points, None, **kw)
        except FileFormatError as exc:
            if "no coordinate columns found" not in str(exc):
                raise
            first = exc
        for names in GEOGRAPHIC_COLS:
            try:
                return PointBlocks(points, names, **kw)
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
    to_crs: Annotated[
        str,
        typer.Option(
            "--to",
            "--to-crs",
            help="CRS of the output, 'enu' or enu:LAT,LON,H (--to-crs: the same option, the "
            "name of cloud transform).",
        ),
    ],
    from_crs: Annotated[
        str | None,
        typer.Option(
            "--from",
            "--from-crs",
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
    commands read. Files of any size are converted block by block, with the memory of a few
    blocks (ids are not checked for duplicates: each row is converted on its own)."""
    single_threaded_blas()
    from .. import crs as _crs

    opt_from = typed_option("--from", "--from-crs")  # the names given, for messages
    opt_to = typed_option("--to", "--to-crs")
    blocks = _read_input(points, cols, id_col)
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
        None if from_crs is None else resolve(from_crs, opt_from),
        opt_from,
        points,
        fix=f"leave {opt_from} out (the file's line is the default) or correct the line",
    )
    if src is None:
        raise InputError(
            f"{points} records no CRS (no '# crs:' line): give the CRS of its coordinates "
            f"with {opt_from} (e.g. {opt_from} EPSG:4979)"
        )
    src_names = crs_column_names(src, opt_from)
    if cols is None and tuple(blocks.columns) in GEOGRAPHIC_COLS and src_names[0] != "lon":
        # degrees read as metres: points on another continent, with no error
        raise InputError(
            f"{points}: columns {', '.join(blocks.columns)} hold longitude and latitude, but "
            f"its CRS {src} has Cartesian coordinates ({', '.join(src_names)}); "
            + (
                f"give the CRS of the points with {opt_from} (e.g. {opt_from} EPSG:4979)"
                if from_crs is not None
                else "correct the file's '# crs:' line (e.g. '# crs: EPSG:4979')"
            )
            + ", or name their columns with --cols"
        )
    dst = resolve(to_crs, opt_to)
    enu_in = _crs.frame_from_text(src) is not None
    enu_out = _crs.frame_from_text(dst) is not None
    if (enu_in or enu_out) and blocks.dim != 3:
        raise InputError(
            f"{points}: 'enu' needs three coordinate columns, found "
            f"{', '.join(blocks.columns)}; choose them with --cols"
        )
    convert_points = _crs.points_converter(src, dst, allow_ballpark=allow_ballpark)
    names = split_names(out_cols) or list(crs_column_names(dst, opt_to)[: blocks.dim])
    check_out_cols(names, blocks.dim, role=blocks.has_roles)
    # the unit of every column written: the output CRS's axes, and for a CRS without a
    # height axis the third coordinate as PROJ passes it through, in the input's unit
    units = _crs.axis_units(dst)[: blocks.dim]
    if len(units) < blocks.dim:
        given = _crs.axis_units(src)
        units.append(
            f"{given[2] if len(given) > 2 else 'the unit of the input'} (the input's "
            f"{blocks.columns[2]}, not converted: {to_crs} has no height axis)"
        )
    comments = [
        f"{src} -> {to_crs}" + (f" (ENU origin {origin})" if frame else "") + "; "
        + ", ".join(f"{n} in {u}" for n, u in zip(names, units))
    ]  # fmt: skip
    comments.append(f"crs: {dst}")

    geographic = not enu_in and _is_geographic(src)
    import numpy as np

    area = None if enu_out else _crs.projected_area_of_use(dst)
    to_lonlat = None
    if area is not None and not geographic:  # where the output points are, from the output
        to_lonlat = _crs.points_converter(dst, _crs.parse_crs(dst).geodetic_crs)
    outside = [0, None]  # count, first id

    def compute(block):
        if geographic:
            _check_geographic(block.ids, block.coords, blocks.columns, src, points)
        out = convert_points(block.coords)
        if area is not None:
            lonlat = block.coords if to_lonlat is None else to_lonlat(out[:, :2])
            mask = area.outside(lonlat[:, 0], lonlat[:, 1])
            if mask.any():
                outside[0] += int(mask.sum())
                if outside[1] is None:
                    outside[1] = block.ids[int(np.argmax(mask))]
        return out, {}

    n = run_point_job(
        blocks, output, names, compute, comments=comments, description="crs convert",
        keep_roles=True,
    )  # fmt: skip
    if outside[0]:
        say(
            f"warning: {outside[0]} of {n} point(s) (first: {outside[1]}) lie outside the area "
            f"of use of {area.describe()}; the projection's distortion grows away from it, "
            "and points far outside usually mean the wrong CRS (e.g. the wrong UTM zone): "
            f"check {opt_to}",
            stderr=True,
        )
    if output is not None:
        say(f"wrote {n} point(s) to {output}", stderr=True)


def _is_geographic(src: str) -> bool:
    """The CRS ``src`` (of --from) is geographic, or compound with a geographic horizontal
    part."""
    from .. import crs as _crs

    c = _crs.parse_crs(src, what=typed_option("--from", "--from-crs"))
    return bool(
        c.is_geographic
        or (c.is_compound and bool(c.sub_crs_list) and c.sub_crs_list[0].is_geographic)
    )


def _check_geographic(ids, coords, columns, src: str, points: Path) -> None:
    """Refuse, by point id, latitudes outside [-90, 90] degrees and longitudes outside
    [-360, 360] degrees in one block of a file (``ids``, ``coords``) whose CRS ``src`` is
    geographic (PROJ would stop with "Invalid latitude" and no point named): most often
    projected or local coordinates given a geographic --from, or columns in the wrong
    order."""
    import numpy as np

    if coords.shape[1] < 2:
        return
    lon, lat = coords[:, 0], coords[:, 1]
    bad = np.flatnonzero(~((np.abs(lat) <= 90.0) & (np.abs(lon) <= 360.0)))
    if bad.size == 0:
        return
    shown = ", ".join(
        f"{ids[i]} (lon {lon[i]:g}, lat {lat[i]:g})" for i in bad[:5]
    ) + (" ..." if bad.size > 5 else "")
    cols = ",".join(columns)
    raise InputError(
        f"{points}: {bad.size} point(s) are not longitude, latitude in degrees ({cols} read as "
        f"lon,lat in {src}): {shown}; if they are projected or local coordinates, give their "
        f"CRS with {typed_option('--from', '--from-crs')} (or the file's '# crs:' line); if the "
        "columns are in another order, "
        "choose them with --cols LON,LAT[,H]"
    )
