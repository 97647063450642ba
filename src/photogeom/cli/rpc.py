"""`photogeom rpc`: rational polynomial (RPC) satellite camera models.

* ``info`` - describe an RPC file (format, offsets and scales, image size, footprint);
* ``project`` - ground points (lon, lat, h) of a CSV to image points (col, row);
* ``localize`` - image points (col, row) at heights to ground points (lon, lat), with a
  status per point;
* ``fit`` - a terrain-dependent RPC from control points (lon, lat, h, col, row);
* ``refine`` - bias compensation of a vendor RPC with control points.

Pixel coordinates: (0, 0) is the centre of the first (top-left) pixel; lon/lat in degrees,
h in metres (ellipsoidal).
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from .._lazy import LazyModule
from ..errors import DegenerateGeometryError, FileFormatError, InputError
from ._common import (
    AlphaOpt,
    IdColOpt,
    JsonOpt,
    OutputCsvOpt,
    ReportOpt,
    check_alpha,
    check_mask,
    check_outputs,
    column_options,
    console,
    crs_column_names,
    finite_or_none,
    json_text,
    options_in_errors,
    say,
    split_control,
    split_names,
    typed_option,
    with_alpha,
    write_outputs,
)
from ._stream import run_point_job, single_threaded_blas

np = LazyModule("numpy")  # imported when a command needs it: quick start-up

app = typer.Typer(
    help="Rational polynomial (RPC) satellite camera models: (0, 0) is the centre of the first "
    "pixel; lon/lat in degrees, h in metres.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


class BiasModel(str, Enum):
    """Image-space correction models of ``refine``."""

    shift = "shift"
    drift = "shift+drift"
    affine = "affine"


class TextStyle(str, Enum):
    """RPC text styles of the writer."""

    ikonos = "ikonos"
    lists = "lists"


def _load_rpc(path: Path):
    from ..rpc import RPC

    if path.is_dir():
        raise FileFormatError(
            f"cannot read {path}: it is a directory; give the RPC file itself (e.g. "
            f"{path}/IMG_RPC.TXT, an _RPC.XML, .RPB or DIMAP file)"
        )
    return RPC.from_file(path)


GROUND_COLS = [["lon", "lat", "h"], ["lon", "lat", "height"], ["longitude", "latitude", "h"],
               ["longitude", "latitude", "height"], ["lon", "lat", "z"]]  # fmt: skip
IMAGE_COLS = [["col", "row"], ["sample", "line"], ["x", "y"]]
HEIGHT_COLS = ["h", "height", "z"]


def _blocks_with(path: Path, cols: str | None, candidates, what: str, id_col: str | None):
    """Point blocks of the first candidate column set present in the file (or ``--cols``)."""
    from ..io import PointBlocks

    option = typed_option("--cols", "--ground-cols", "--image-cols")  # the name given
    if cols is not None:
        with column_options(option):
            return PointBlocks(path, split_names(cols), id_column=id_col, role_column=None)
    for cand in candidates:
        try:
            return PointBlocks(path, cand, id_column=id_col, role_column=None)
        except FileFormatError as exc:
            if "not found; the file has columns" not in str(exc):
                raise  # a real problem of the file, not a missing column set
    raise InputError(
        f"{path}: cannot find the {what} columns; expected "
        + " or ".join(",".join(c) for c in candidates)
        + f" (or name them with {option})"
    )


@app.command("info")
def info(
    rpc_file: Annotated[Path, typer.Argument(help="RPC file (any supported format).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of text.")] = False,
) -> None:
    """Describe an RPC: format, offsets and scales, image size, footprint at HEIGHT_OFF."""
    from ..rpc.localization import approximate_inverse

    rpc = _load_rpc(rpc_file)
    fp = rpc.footprint()
    inv = approximate_inverse(rpc)
    if as_json:
        data = {
            "file": str(rpc_file),
            "format": rpc.source,
            "pixel_convention": "(0, 0) = centre of the first pixel; col right, row down",
            "metadata": rpc.to_dict(),
            "image_size": list(rpc.image_size) if rpc.image_size else None,
            "image_bounds": list(rpc.image_bounds),
            "height_range_m": list(rpc.height_range),
            "footprint_lon_lat_deg": fp.tolist(),
            "footprint_height_m": rpc.height_off,
            "has_image_to_ground_polynomials": rpc.direct is not None,
            "approximate_inverse_max_error_px": inv.max_error_px,
            "notes": list(rpc.notes),
        }
        typer.echo(json_text(data), nl=False)
        return
    lines = [f"{rpc_file}", rpc.summary()]
    lines.append(f"  footprint at h = {rpc.height_off:g} m (lon, lat deg):")
    for name, (lo, la) in zip(("top-left", "top-right", "bottom-right", "bottom-left"), fp):
        lines.append(f"    {name:<13} {lo:.8f} {la:.8f}")
    lines.append(
        f"  localisation start: approximate inverse within {inv.max_error_px:.2g} px "
        f"({inv.n_points} grid points)"
    )
    say("\n".join(lines))


def _say_warnings(caught: list, seen: set) -> None:
    """The warnings caught around a block, each text once, as ``warning: ...`` lines; numpy's
    floating-point warnings from photogeom's code are left out, as the command line's display
    does (see :func:`photogeom.cli.main._show_warning`): the statuses name those points."""
    from .main import _in_photogeom

    for w in caught:
        if w.category is RuntimeWarning and _in_photogeom(w.filename):
            continue
        text = str(w.message)
        if text not in seen:
            seen.add(text)
            say(f"warning: {text}", stderr=True)


@app.command("project")
def project(
    rpc_file: Annotated[Path, typer.Argument(help="RPC file.")],
    points: Annotated[Path, typer.Argument(help="CSV of ground points: id, lon, lat, h.")],
    output: OutputCsvOpt = None,
    cols: Annotated[
        str | None,
        typer.Option(
            "--cols",
            "--ground-cols",
            help="Ground columns lon,lat,h (default: found by name); --ground-cols is the same "
            "option (the name of rpc fit and rpc refine).",
        ),
    ] = None,
    id_col: IdColOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of CSV.")] = False,
    crs: Annotated[
        str | None,
        typer.Option(
            "--crs",
            help="CRS of the ground points (EPSG:32632, WKT, PROJ string or enu:LAT,LON,H; "
            "columns x,y,z found by name), converted by PROJ to the RPC's WGS 84 (EPSG:4979). "
            "Default: the '# crs:' line of POINTS, else lon,lat,h in EPSG:4979.",
            show_default=False,
        ),
    ] = None,
    allow_ballpark: Annotated[
        bool, typer.Option(help="Accept an approximate PROJ datum shift (--crs).")
    ] = False,
) -> None:
    """Project ground points (lon, lat in degrees, h in metres) into the image (col, row px).

    Files of any size are read and written block by block (a progress bar on a terminal).
    """
    from ._common import option_or_file_crs

    check_outputs({"RPC_FILE": rpc_file}, output=output)  # -o POINTS is allowed (read first)
    single_threaded_blas()
    rpc = _load_rpc(rpc_file)
    given = crs is not None
    crs = option_or_file_crs(
        crs,
        "--crs",
        points,
        fix="leave --crs out (the file's line is the default) or convert the points first "
        "with photogeom crs convert",
    )
    if not given and crs is not None and _is_wgs84_3d(crs):
        crs = None
    if crs is None:
        blocks = _blocks_with(points, cols, GROUND_COLS, "ground (lon, lat, h)", id_col)
        to_wgs84 = None
    else:
        blocks = _blocks_with(points, cols, _CRS_COLS, "ground (x, y, z)", id_col)
        to_wgs84 = _input_crs(crs, allow_ballpark)
        names = crs_column_names(crs.strip(), "--crs")
        if cols is None and list(blocks.columns) in GROUND_COLS and names[0] != "lon":
            # degrees read as metres: pixels far outside the image, with no error
            where = f"--crs {crs}" if given else f"the file's CRS {crs}"
            fix = (
                "give the CRS of the points (leave --crs out for lon, lat, h of WGS 84)"
                if given
                else "correct the file's '# crs:' line (e.g. '# crs: EPSG:4979')"
            )
            raise InputError(
                f"{points}: columns {', '.join(blocks.columns)} hold longitude and latitude, "
                f"but {where} has Cartesian coordinates ({', '.join(names)}); {fix}, or name "
                "their columns with --cols"
            )
    if blocks.dim != 3:
        raise InputError(
            f"--cols: need three ground columns lon,lat,h, got {', '.join(blocks.columns)}"
        )
    seen: set = set()

    def compute(block):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            c = block.coords if to_wgs84 is None else to_wgs84(block.coords)
            col, row = rpc.project(c[:, 0], c[:, 1], c[:, 2])
        _say_warnings(caught, seen)
        return np.column_stack([col, row]), {}

    if as_json:
        rows = []
        for block in blocks:
            xy, _ = compute(block)
            rows += [
                {"id": i, "col": finite_or_none(c), "row": finite_or_none(r)}
                for i, (c, r) in zip(block.ids.to_pylist(), xy)
            ]
        data = {
            "rpc": str(rpc_file),
            "pixel_convention": "(0, 0) = centre of the first pixel",
            "units": {"col": "px", "row": "px"},
            "points": rows,
        }
        typer.echo(json_text(data), nl=False)
        return
    n = run_point_job(
        blocks, output, ["col", "row"], compute,
        comments=[f"projected with {rpc_file}; (0, 0) = centre of the first pixel, px"],
        description="rpc project",
    )  # fmt: skip
    if output is not None:
        say(f"wrote {n} point(s) to {output}", stderr=True)


def _extrapolated(rpc, col, row, h, lon, lat, converged) -> np.ndarray:
    """Converged points outside the domain the RPC was fitted on (the projection's warning
    limit on normalised image or ground coordinates)."""
    from ..rpc.domain import DOMAIN_LIMIT

    sn, ln = rpc.normalize_image(col, row)
    with np.errstate(invalid="ignore"):
        L, P, H = rpc.normalize_ground(lon, lat, h)
        worst = np.max(np.abs(np.vstack([sn, ln, L, P, H])), axis=0)
    return converged & (worst > DOMAIN_LIMIT)


@app.command("localize")
@options_in_errors(tol="--tol", max_iter="--max-iter")
def localize(
    rpc_file: Annotated[Path, typer.Argument(help="RPC file.")],
    points: Annotated[Path, typer.Argument(help="CSV of image points: id, col, row[, h].")],
    output: OutputCsvOpt = None,
    height: Annotated[
        float | None,
        typer.Option("--height", help="Height (m) of every point, instead of an h column."),
    ] = None,
    cols: Annotated[
        str | None,
        typer.Option(
            "--cols",
            "--image-cols",
            help="Image columns col,row (or col,row,h) (default: found by name); --image-cols "
            "is the same option (the name of rpc fit and rpc refine).",
        ),
    ] = None,
    id_col: IdColOpt = None,
    tol: Annotated[float, typer.Option(help="Convergence tolerance (px).")] = 1e-6,
    max_iter: Annotated[int, typer.Option(help="Newton iterations per point.")] = 20,
    strict: Annotated[
        bool, typer.Option(help="Fail (exit 2) when a point does not converge.")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of CSV.")] = False,
    crs: Annotated[
        str | None,
        typer.Option(
            "--crs",
            help="Write the ground points in this CRS (EPSG:32632, WKT, PROJ string or "
            "enu:LAT,LON,H; columns lon,lat,h for a geographic CRS, E,N,U for a local frame, "
            "else x,y,z), converted by PROJ from the RPC's WGS 84 "
            "(EPSG:4979: lon, lat, ellipsoidal h). Default: lon,lat,h in EPSG:4979.",
            show_default=False,
        ),
    ] = None,
    allow_ballpark: Annotated[
        bool, typer.Option(help="Accept an approximate PROJ datum shift (--crs).")
    ] = False,
) -> None:
    """Ground points (lon, lat) of image points at given heights, with a status per point.

    Status: converged; extrapolated (converged, but the point or its height lies outside the
    domain the RPC was fitted on, so the position is not to be trusted); limit_reached or
    diverged (empty lon/lat, 'nan': nothing is guessed). Files of any size are read and
    written block by block (a progress bar on a terminal).
    """
    check_outputs({"RPC_FILE": rpc_file}, output=output)  # -o POINTS is allowed (read first)
    single_threaded_blas()
    import math

    from ..errors import ConvergenceError
    from ..rpc import LocalizationStatus

    if height is not None and not math.isfinite(height):
        raise InputError(
            f"--height {height}: give the ellipsoidal height in metres, a finite number"
        )
    rpc = _load_rpc(rpc_file)
    to_crs = None if crs is None else _output_crs(crs, allow_ballpark)
    if height is None:
        cands = [[*c, hc] for c in IMAGE_COLS for hc in HEIGHT_COLS]
        what = "image and height (col, row, h)"
        try:
            blocks = _blocks_with(points, cols, cands, what, id_col)
        except InputError:
            if cols is None:
                raise InputError(
                    f"{points}: no height column (h, height or z) next to the image columns; "
                    "add one, or give every point the same height with --height METRES "
                    "(ellipsoidal)"
                ) from None
            raise
    else:
        blocks = _blocks_with(points, cols, IMAGE_COLS, "image (col, row)", id_col)
    if height is None and blocks.dim != 3:
        raise InputError(
            f"{points}: columns {', '.join(blocks.columns)} give no height; add an h column to "
            "--cols (col,row,h) or give every point the same height with --height METRES"
        )
    import pyarrow as pa
    import pyarrow.compute as pc

    labels = [s.name.lower() for s in sorted(LocalizationStatus)] + ["extrapolated"]
    counts = {name: 0 for name in labels}
    seen: set = set()

    def compute(block):
        c = block.coords
        h = np.full(len(block), float(height)) if height is not None else c[:, 2]
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                res = rpc.localize(
                    c[:, 0], c[:, 1], h, tol=tol, max_iter=max_iter, full_output=True,
                    on_failure="raise" if strict else "nan",
                )  # fmt: skip
            except ConvergenceError as exc:
                raise ConvergenceError(
                    f"{exc} (without --strict, such points get status limit_reached or "
                    "diverged and empty lon/lat)",
                    exc.iterations,
                    exc.result,
                ) from None
        _say_warnings(caught, seen)
        code = res.status.astype(np.int64)
        code[_extrapolated(rpc, c[:, 0], c[:, 1], h, res.lon, res.lat, res.converged)] = 3
        for k, v in enumerate(np.bincount(code, minlength=4)):
            counts[labels[k]] += int(v)
        status = pc.take(pa.array(labels), pa.array(code))
        xyz = np.column_stack([res.lon, res.lat, h])
        if to_crs is not None:
            xyz = to_crs[1](xyz)
        return xyz, {"status": status}, res

    def report():
        bad = counts["limit_reached"] + counts["diverged"]
        total = sum(counts.values())
        if bad:
            say(
                f"warning: {bad} of {total} point(s) did not converge (status column); their "
                "lon/lat are nan",
                stderr=True,
            )
        if counts["extrapolated"]:
            say(
                f"warning: {counts['extrapolated']} of {total} point(s) lie outside the domain "
                "of the RPC (status extrapolated); their lon/lat are extrapolations",
                stderr=True,
            )

    # the unit of every coordinate written (--json: "units"; a CSV: its comment)
    if to_crs is None:
        units = {"lon": "deg", "lat": "deg", "h": "m"}
    else:
        units = _crs_column_units(to_crs[0], to_crs[2])
    if as_json:
        rows = []
        keys = ("lon", "lat", "h") if to_crs is None else to_crs[2]
        for block in blocks:
            xyz, more, res = compute(block)
            rows += [
                {"id": i, **{k: finite_or_none(v) for k, v in zip(keys, p)}, "status": s,
                 "iterations": int(it)}
                for i, p, s, it in zip(
                    block.ids.to_pylist(), xyz, more["status"].to_pylist(), res.iterations
                )
            ]  # fmt: skip
        report()
        data = {"rpc": str(rpc_file), "tol_px": tol, "counts": counts, "points": rows}
        data["crs"] = "EPSG:4979" if to_crs is None else to_crs[0]
        data["units"] = units
        typer.echo(json_text(data), nl=False)
        return
    if to_crs is None:
        names = ["lon", "lat", "h"]
        comments = [
            f"localised with {rpc_file}; lon, lat in degrees, h in metres; tol {tol:g} px",
            "crs: EPSG:4979",
        ]
    else:
        names = list(to_crs[2])
        comments = [
            f"localised with {rpc_file}; tol {tol:g} px; converted from EPSG:4979 (lon, lat, "
            "ellipsoidal h) by PROJ; " + ", ".join(f"{k} in {u}" for k, u in units.items()),
            f"crs: {to_crs[0]}",
        ]
    n = run_point_job(
        blocks, output, names, lambda b: compute(b)[:2], extra=["status"],
        comments=comments, description="rpc localize",
    )  # fmt: skip
    report()
    if output is not None:
        say(f"wrote {n} point(s) to {output}", stderr=True)


_CRS_COLS = [["x", "y", "z"], ["X", "Y", "Z"], ["E", "N", "H"], ["E", "N", "U"],
             ["easting", "northing", "height"], *GROUND_COLS]  # fmt: skip


def _is_wgs84_3d(text: str) -> bool:
    from .. import crs as _crs

    return _crs.frame_from_text(text) is None and _crs.parse_crs(text) == _crs.parse_crs(
        "EPSG:4979"
    )


def _input_crs(crs: str, allow_ballpark: bool):
    """A function converting (n, 3) points of ``crs`` to lon, lat, h of WGS 84."""
    from .. import crs as _crs

    text = crs.strip()
    if _crs.frame_from_text(text) is None:
        _crs.parse_crs(text, what="--crs")

    # the PROJ operation built once, not once per block of a streamed file
    return _crs.points_converter(text, "EPSG:4979", allow_ballpark=allow_ballpark)


def _crs_column_units(text: str, names) -> dict[str, str]:
    """The unit of each output column ``names`` of ``rpc localize --crs text``: those of the
    CRS's axes (``deg`` for degrees, ``ftUS`` for US survey feet), and for a CRS of two axes
    the third column's, the ellipsoidal height of WGS 84 that PROJ passes through (m)."""
    from ..crs import axis_units

    units = axis_units(text)[:3]
    if len(units) < 3:
        units.append("m (ellipsoidal height of WGS 84, not converted: the CRS has no height)")
    return dict(zip(names, units))


def _output_crs(crs: str, allow_ballpark: bool):
    """(CRS text, function converting (n, 3) lon, lat, h of WGS 84 into it (rows with NaN
    stay NaN), output column names) for ``--crs``: ``lon, lat, h`` for a geographic CRS
    (what ``rpc project`` and ``crs convert`` read), ``E, N, U`` for a local frame, else
    ``x, y, z``."""
    from .. import crs as _crs

    text = crs.strip()
    names = crs_column_names(text, "--crs")  # checks the CRS text as well

    # the PROJ operation built once, not once per block of a streamed file
    between = _crs.points_converter("EPSG:4979", text, allow_ballpark=allow_ballpark)

    def convert(lonlath):
        out = np.full_like(lonlath, np.nan)
        ok = np.all(np.isfinite(lonlath), axis=1)
        if np.any(ok):
            out[ok] = between(lonlath[ok])
        return out

    return text, convert, names


def _control(points: Path, ground_cols: str, image_cols: str, id_col: str | None, check_ids):
    from ..io import read_point_pairs
    from ._common import option_or_file_crs

    rec = option_or_file_crs(None, "--crs", points)
    if rec is not None and not _is_wgs84_3d(rec):
        raise InputError(
            f"{points} records the CRS {rec} ('# crs:' line) but the ground columns of control "
            "points are lon, lat (degrees) and ellipsoidal h of WGS 84 (EPSG:4979); convert "
            "the ground coordinates first (photogeom crs convert --to EPSG:4979 --out-cols "
            "lon,lat,h)"
        )

    with column_options("--ground-cols", source="--ground-cols", target="--image-cols"):
        pairs = read_point_pairs(
            points, split_names(ground_cols), split_names(image_cols), id_column=id_col
        )
    return pairs, check_mask(pairs.ids, pairs.check_mask, check_ids)


def _weights_are_relative(points: Path) -> bool:
    """True when the weights :func:`read_point_pairs` found in ``points`` come from a
    ``weight``/``w`` column (unitless, relative to ``--sigma``), False for a
    ``sigma``/``sd``/``std`` column (pixels) -- the reader's own order of preference."""
    from ..io.csvblocks import DelimitedText
    from ..io.points import WEIGHT_COLUMNS

    header = set(DelimitedText(points).header)
    return any(c in header for c in WEIGHT_COLUMNS)


def _sigmas(pairs, mask, sigma: float, points: Path):
    """Standard deviations (px) of the control points' image coordinates: ``--sigma``, or
    ``--sigma / sqrt(weight)`` with a weight column, or a sigma column's values (px)."""
    if pairs.weights is None:
        return sigma
    w = pairs.weights[~mask]
    scale = sigma if _weights_are_relative(points) else 1.0
    return scale / np.sqrt(w)


# --- options shared by ``fit`` and ``refine`` ---------------------------------------------------

SigmaOpt = Annotated[
    float,
    typer.Option(
        help="Image measurement std. dev. (px); with a weight column, that of weight 1 "
        "(a point's is sigma / sqrt(weight)); a sigma column (px) replaces it."
    ),
]
GroundColsOpt = Annotated[
    str, typer.Option(help="Ground columns of the CSV (lon deg, lat deg, h m).")
]
ImageColsOpt = Annotated[str, typer.Option(help="Image columns of the CSV (px).")]
CheckIdsOpt = Annotated[
    str | None,
    typer.Option(
        help="Comma-separated ids of check points (default: rows whose role column says 'check')."
    ),
]
StyleOpt = Annotated[TextStyle, typer.Option(help="Text style of the written RPC.")]


def _report_html(title: str, subtitle: str, fit, image_ctrl, image_chk, intro: str) -> str:
    from ..report import Report

    rep = Report(title, subtitle=subtitle)
    rep.add_text("Input", intro, pre=False)
    rep.add_fit(
        fit,
        title=f"{title} ({fit.method})",
        points=image_ctrl,
        check_points=image_chk if image_chk is not None and len(image_chk) else None,
        point_labels=("col", "row"),
        point_unit="px",
        y_down=True,
    )
    return rep.to_html()


@app.command("fit")
@options_in_errors(order="--order", regularization="--regularization", sigma="--sigma")
def fit(
    points: Annotated[
        Path, typer.Argument(help="CSV of control points: id, lon, lat, h, col, row[, role].")
    ],
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the fitted RPC (text) here.")
    ] = None,
    order: Annotated[
        int, typer.Option(help="Polynomial degree 1, 2 or 3 (needs 7, 19, 39 control points).")
    ] = 1,
    regularization: Annotated[
        float, typer.Option(help="Tikhonov parameter (normalised units).")
    ] = 1e-6,
    sigma: SigmaOpt = 1.0,
    ground_cols: GroundColsOpt = "lon,lat,h",
    image_cols: ImageColsOpt = "col,row",
    id_col: IdColOpt = None,
    check_ids: CheckIdsOpt = None,
    style: StyleOpt = TextStyle.ikonos,
    alpha: AlphaOpt = None,
    as_json: JsonOpt = False,
    report: ReportOpt = None,
) -> None:
    """Fit a terrain-dependent RPC to control points (regularised least squares).

    Needs at least 7, 19 or 39 control points for degree 1, 2 or 3. Residuals are
    computed minus observed (px); check points do not enter the fit.
    """
    from ..rpc import fit_rpc_to_points
    from ..rpc.fitting import UnstableFitError, unstable_fit_message

    check_outputs({"POINTS": points}, output=output, report=report)
    alpha = check_alpha(alpha)

    pairs, mask = _control(points, ground_cols, image_cols, id_col, check_ids)
    sig = _sigmas(pairs, mask, sigma, points)
    if np.ndim(sig):
        raise InputError(
            "fit: per-point sigma/weight columns are not supported for RPC fitting; use --sigma"
        )
    ground, image, kw = split_control(pairs.ids, pairs.source, pairs.target, mask)
    try:
        result = fit_rpc_to_points(
            ground, image, order=order, regularization=regularization, sigma=float(sig), **kw
        )
    except UnstableFitError as exc:  # the same refusal in the command's option names
        raise DegenerateGeometryError(
            unstable_fit_message(*exc.details, option="--regularization", order_option="--order")
        ) from exc
    _finish(
        with_alpha(result, alpha), output, style, as_json, report, points, pairs, mask,
        "Terrain-dependent RPC fit",
    )


@app.command("refine")
@options_in_errors(sigma="--sigma")
def refine(
    rpc_file: Annotated[Path, typer.Argument(help="Vendor RPC file.")],
    points: Annotated[
        Path, typer.Argument(help="CSV of control points: id, lon, lat, h, col, row[, role].")
    ],
    model: Annotated[BiasModel, typer.Option(help="Image-space correction.")] = BiasModel.affine,
    output: Annotated[
        Path | None,
        typer.Option(
            "--output",
            "-o",
            help="Write the corrected RPC (text). Shift and per-axis scale corrections are "
            "written into the offsets exactly; others are re-fitted (the re-fit error is shown).",
        ),
    ] = None,
    sigma: SigmaOpt = 1.0,
    ground_sigma: Annotated[
        str | None,
        typer.Option(
            help="Std. dev. of the control points' ground coordinates (m): one number or "
            "east,north,up. Propagated into image space; default: ground taken as exact.",
            show_default=False,
        ),
    ] = None,
    ground_cols: GroundColsOpt = "lon,lat,h",
    image_cols: ImageColsOpt = "col,row",
    id_col: IdColOpt = None,
    check_ids: CheckIdsOpt = None,
    style: StyleOpt = TextStyle.ikonos,
    alpha: AlphaOpt = None,
    as_json: JsonOpt = False,
    report: ReportOpt = None,
) -> None:
    """Bias-compensate a vendor RPC with control points (shift, shift+drift or affine).

    Prints the correction parameters with standard deviations, sigma0, and the residuals
    (computed minus observed, px) of control and check points.
    """
    from ..rpc import refine_rpc

    # the vendor RPC too: a refined RPC written over it could not be refined again
    check_outputs({"RPC_FILE": rpc_file, "POINTS": points}, output=output, report=report)
    alpha = check_alpha(alpha)
    rpc = _load_rpc(rpc_file)
    pairs, mask = _control(points, ground_cols, image_cols, id_col, check_ids)
    ground, image, kw = split_control(pairs.ids, pairs.source, pairs.target, mask)
    sig = _sigmas(pairs, mask, sigma, points)
    gsig = None if ground_sigma is None else _ground_sigma(ground_sigma)
    result = refine_rpc(
        rpc, ground, image, model=BiasModel(model).value, sigma=sig, ground_sigma=gsig, **kw
    )
    _finish(with_alpha(result, alpha), output, style, as_json, report, points, pairs, mask,
            "RPC bias compensation", source_rpc=rpc_file)  # fmt: skip


def _ground_sigma(text: str) -> np.ndarray:
    """``--ground-sigma``: one number or east,north,up (m)."""
    from ..numbers import parse_decimal

    parts = [p.strip() for p in text.split(",")]
    try:
        values = np.array([parse_decimal(p) for p in parts], dtype=float)
    except (ValueError, InputError):
        values = np.array([])
    if values.size not in (1, 3) or not np.all(np.isfinite(values)) or np.any(values < 0):
        raise InputError(
            f"--ground-sigma: expected one number or east,north,up (metres >= 0), got {text!r}"
        )
    return values if values.size == 3 else np.full(3, values[0])


def _writable(result):
    """The model to write and a note (re-fitting corrections that cannot be folded)."""
    model = result.model
    if model.correction is None or model.correction_is_foldable:
        return model.with_correction_folded(), None
    from ..rpc import fit_rpc

    fp = np.vstack([model.footprint(h) for h in model.height_range])
    lo, hi = fp.min(axis=0), fp.max(axis=0)
    pad = 0.05 * (hi - lo)
    bounds = [[lo[0] - pad[0], hi[0] + pad[0]], [lo[1] - pad[1], hi[1] + pad[1]],
              list(model.height_range)]  # fmt: skip
    refit = fit_rpc(model, bounds, image_size=model.image_size)
    note = (
        "the correction has cross terms; the written RPC is a terrain-independent re-fit of the "
        f"corrected model (largest check-grid error {refit.extras['check_max_px']:.2g} px)"
    )
    # the vendor's random error still applies; its bias error described the removed bias
    return replace(
        refit.model, source="re-fit of a bias-compensated RPC", err_rand=model.err_rand
    ), note


def _finish(result, output, style, as_json, report, points, pairs, mask, title, source_rpc=None):
    from ..report import print_fit
    from ..rpc.writer import format_rpc

    outputs: list[tuple[Path, str]] = []
    notes = []
    written = None
    if output is not None:
        written, note = _writable(result)
        if note:
            notes.append(note)
            result = replace(result, notes=(*result.notes, note))
    subtitle = str(points) if source_rpc is None else f"{source_rpc} + {points}"
    intro = (
        f"{int((~mask).sum())} control and {int(mask.sum())} check point(s) from {points}; "
        "ground lon, lat (deg), h (m); image col, row (px, (0, 0) = centre of the first pixel)."
    )
    if report is not None:
        ctrl = pairs.target[~mask]
        chk = pairs.target[mask] if mask.any() else None
        outputs.append((report, _report_html(title, subtitle, result, ctrl, chk, intro)))
    if written is not None:
        outputs.insert(0, (output, format_rpc(written, style=TextStyle(style).value)))
    write_outputs(outputs)
    if as_json:
        data = result.to_dict()
        data["input"] = {"points": str(points), "n_control": int((~mask).sum()),
                         "n_check": int(mask.sum())}  # fmt: skip
        if written is not None:
            data["output_rpc"] = str(output)
        typer.echo(json_text(data), nl=False)
        return
    out = console()
    say(intro, out)
    print_fit(result, console=out)
    for path, _ in outputs:
        say(f"wrote {path}", out)
