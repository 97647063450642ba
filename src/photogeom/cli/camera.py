"""`photogeom camera`: frame camera models: projection and the DLT.

* ``camera project``: ground points -> image coordinates with the collinearity equations;
* ``camera dlt estimate``: the 11 DLT parameters from control points (linear, rigorous or
  constrained), with statistics, residuals and a report;
* ``camera dlt convert``: interior + exterior orientation -> DLT, or DLT -> orientations;
* ``camera convert``: a calibration between Metashape XML, camera JSON, OpenCV YAML/XML and
  COLMAP ``cameras.txt``.

The camera is given by options (``--f``, ``--x0``, ``--y0``, ``--unit``, or ``--pixel-size``
and ``--principal-point`` for a digital camera), by a calibration file (``--calibration``:
Metashape XML, camera JSON, OpenCV FileStorage YAML/XML/JSON or a COLMAP ``cameras.txt`` of one
camera, told apart by content) or by a JSON file (``--camera``: the output of
``--output-params``, or ``{"interior": {...}, "exterior": {...}}``; a calibration of another
tool gives the interior orientation only). Angles on the command line are in
``--angle-unit`` (degrees by default); inside the library they are radians.
"""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from .._lazy import LazyModule
from ..errors import FileFormatError, InputError
from ._common import (
    AlphaOpt,
    AngleUnit,
    IdColOpt,
    JsonOpt,
    OutputCsvOpt,
    ReportOpt,
    check_alpha,
    check_mask,
    check_outputs,
    column_options,
    console,
    emit_points,
    finite_or_none,
    image_size_option,
    json_text,
    options_in_errors,
    say,
    split_control,
    split_names,
    split_numbers,
    typed_option,
    with_alpha,
    write_outputs,
)

np = LazyModule("numpy")  # imported when a command needs it: quick start-up

app = typer.Typer(
    help="Frame camera models: projection, DLT, calibration files.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
dlt_app = typer.Typer(
    help="Direct linear transformation: estimate, convert.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(dlt_app, name="dlt")


class ImageUnit(str, Enum):
    """Image coordinate units."""

    mm = "mm"
    px = "px"


class Behind(str, Enum):
    """What to do with points behind the camera."""

    raise_ = "raise"
    nan = "nan"


def read_json(path: Path) -> dict:
    """A JSON object from a file, with clear errors (see :mod:`photogeom.io.jsonfile`).

    A pipe (``--camera <(cat cam.json)``, a named pipe) is read once: its bytes are kept
    for the other reads of the same pipe in this command (its format, its CRS, the interior
    and the exterior orientation; a second read used to wait for ever)."""
    from ..io.jsonfile import read_json_object

    return read_json_object(path)


def read_parameters_json(path: Path) -> dict:
    """:func:`read_json`, descending into ``model_parameters`` when the file has it (the
    ``--output-params`` / ``--json`` output of the estimating commands)."""
    data = read_json(path)
    if isinstance(data.get("model_parameters"), dict):
        data = data["model_parameters"]
    return data


def _is_foreign_calibration(path: Path, content_format) -> bool:
    """Whether a regular file or a pipe is a calibration in another tool's format (not
    JSON), told by its content; a pipe is read once, its bytes kept for the reader."""
    from ..io.jsonfile import MAX_JSON_BYTES
    from ..io.sources import input_kind, pipe_bytes

    kind = input_kind(path)
    try:
        if kind == "pipe":
            head = pipe_bytes(path, MAX_JSON_BYTES)[:4096]
        elif kind == "file":
            with open(path, "rb") as fh:
                head = fh.read(4096)
        else:
            return False  # read_json reports it
    except OSError:
        return False  # read_json reports it
    return content_format(head) in ("opencv", "colmap", "metashape")


def camera_from_json(path: Path):
    """(InteriorOrientation or None, ExteriorOrientation or None) from a JSON file.

    Accepts a ``FrameCamera.to_dict()``, the ``--output-params``/``--json`` output of
    ``orient resection`` (its ``model_parameters``) or of ``camera dlt estimate`` (the
    orientation decomposed from the DLT, its ``orientation``), a bare interior orientation,
    or a DLT (``L1..L11`` with its ``unit``, the ``--json`` output of ``camera dlt convert``
    from a camera), decomposed into interior and exterior orientation.
    """
    from ..camera import ExteriorOrientation, InteriorOrientation
    from ..camera.calibration_files import calibration_content_format
    from ..io.jsonfile import build_from_json

    if _is_foreign_calibration(path, calibration_content_format):
        # an OpenCV YAML/XML, a COLMAP cameras.txt or a Metashape XML: the interior only
        return read_calibration_option(path, "--camera").interior_orientation(), None
    raw = read_json(path)
    if "camera_matrix" in raw and not any(k in raw for k in ("calibration", "interior")):
        # cv2.FileStorage's JSON (a .json written by OpenCV), as --calibration reads it
        return read_calibration_option(path, "--camera").interior_orientation(), None
    data = raw
    if isinstance(raw.get("model_parameters"), dict):  # as read_parameters_json, one read
        data = raw["model_parameters"]
    orientation = raw.get("orientation") if isinstance(raw, dict) else None
    if (
        not any(k in data for k in ("interior", "exterior", "f"))
        and isinstance(orientation, dict)
        and ("interior" in orientation or "exterior" in orientation)
    ):  # camera dlt estimate: L1..L11 in model_parameters, the camera in orientation
        data = orientation
    if "interior" in data or "exterior" in data:
        io = eo = None
        if "interior" in data:
            io = build_from_json(
                InteriorOrientation.from_dict, data["interior"], path, "interior orientation"
            )
        if "exterior" in data:
            eo = build_from_json(
                ExteriorOrientation.from_dict, data["exterior"], path, "exterior orientation"
            )
        return io, eo
    if "f" in data:
        io = build_from_json(InteriorOrientation.from_dict, data, path, "interior orientation")
        return io, None
    if str(data.get("model", "")).lower() == "dlt" or all(f"L{k}" in data for k in range(1, 12)):
        # a DLT (camera dlt convert --json): the camera it holds, decomposed as camera dlt
        # convert --params does
        from ..camera import DLT, orientation_from_dlt
        from ..errors import PhotogeomError

        try:
            dlt = DLT.from_dict(data)
            return orientation_from_dlt(dlt, unit=dlt.unit)
        except PhotogeomError as exc:
            raise FileFormatError(
                f"{path}: a DLT (L1..L11) that gives no camera: {exc}; give a camera JSON "
                "(interior and exterior orientation)"
            ) from None
    raise FileFormatError(
        f"{path}: no camera found (expected 'interior'/'exterior' entries, e.g. the output of "
        "'photogeom orient resection --output-params' or 'camera dlt estimate --output-params')"
    )


def read_calibration_option(path: Path, option: str):
    """The calibration of a ``--calibration``/``--camera`` file: Metashape XML, camera JSON,
    OpenCV FileStorage YAML/XML/JSON or a COLMAP ``cameras.txt`` of one camera (by content).

    Parameters
    ----------
    path : Path
        The file.
    option : str
        The option's name, for messages.

    Returns
    -------
    MetashapeCalibration
        The frame-camera calibration (px).

    Raises
    ------
    FileFormatError
        As :func:`photogeom.camera.calibration_files.read_calibration_file`, the message
        starting with the option's name.
    """
    from ..camera.calibration_files import read_calibration_file
    from ..camera.metashape_export import CHOOSE_SENSOR

    try:
        return read_calibration_file(path)[0]
    except FileFormatError as exc:
        text = str(exc).replace(
            CHOOSE_SENSOR,
            f"write its calibration first with 'photogeom camera convert {path} --sensor ID "
            f"camera.xml' and give {option} camera.xml",
        )
        raise FileFormatError(f"{option} {text}") from None


def build_interior(
    *,
    camera: Path | None,
    calibration: Path | None,
    f: float | None,
    x0: float,
    y0: float,
    unit: ImageUnit,
    pixel_size: float | None,
    principal_point: str | None,
    required: bool = True,
):
    """The interior orientation from the command-line options (see the module docstring)."""
    from ..camera import InteriorOrientation

    sources = [s for s in (camera, calibration, f) if s is not None]
    if len(sources) > 1:
        raise InputError("give the camera once: --camera, --calibration or --f")
    unit = ImageUnit(unit).value
    if calibration is not None:
        return read_calibration_option(calibration, "--calibration").interior_orientation()
    if camera is not None:
        io, _ = camera_from_json(camera)
        if io is None and required:
            raise InputError(f"{camera}: holds no interior orientation")
        return io
    if f is None:
        if required:
            raise InputError(
                "no camera given: use --f (principal distance) with --unit, --calibration "
                "(Metashape XML) or --camera (JSON)"
            )
        return None
    import math

    for name, value in (("--f", f), ("--x0", x0), ("--y0", y0), ("--pixel-size", pixel_size)):
        if value is not None and not math.isfinite(value):
            raise InputError(f"{name} {value}: give a finite number")
    if principal_point is not None:
        col, row = split_numbers(principal_point, 2, "--principal-point")
        return InteriorOrientation.digital(f, col, row, unit=unit, pixel_size=pixel_size)
    return InteriorOrientation(f, x0, y0, unit=unit, pixel_size=pixel_size)


def refuse_ignored_camera_options(
    *,
    camera: Path | None,
    calibration: Path | None,
    f: float | None,
    x0: float | None,
    y0: float | None,
    unit: ImageUnit | None,
    pixel_size: float | None,
    principal_point: str | None,
) -> None:
    """Refuse camera options that the chosen source of the interior orientation ignores.

    Parameters
    ----------
    camera, calibration, f
        The sources of the camera (``--camera``, ``--calibration``, ``--f``).
    x0, y0, unit, pixel_size, principal_point
        The other camera options; None when not given on the command line.

    Raises
    ------
    InputError
        ``--x0``, ``--y0``, ``--unit``, ``--pixel-size`` or ``--principal-point`` with
        ``--camera`` or ``--calibration`` (the file gives the whole interior orientation),
        or ``--x0``/``--y0`` with ``--principal-point`` (two principal points). More than one
        source is left to :func:`build_interior`.
    """
    if sum(s is not None for s in (camera, calibration, f)) > 1:
        return
    given = {
        "--x0": x0,
        "--y0": y0,
        "--unit": unit,
        "--pixel-size": pixel_size,
        "--principal-point": principal_point,
    }
    if camera is not None or calibration is not None:
        source = "--camera" if camera is not None else "--calibration"
        ignored = [name for name, v in given.items() if v is not None]
        if ignored:
            raise InputError(
                f"{', '.join(ignored)} cannot be used with {source}: the camera file gives the "
                "interior orientation (principal distance, principal point, unit, pixel size); "
                f"leave {'them' if len(ignored) > 1 else 'it'} out, or give the camera with "
                "--f and these options instead"
            )
    elif principal_point is not None:
        both = [name for name in ("--x0", "--y0") if given[name] is not None]
        if both:
            raise InputError(
                f"{' and '.join(both)} and --principal-point both give the principal point; "
                "give it once: --principal-point COL,ROW (pixels) or --x0/--y0 (in --unit)"
            )


def interior_from_options(
    *,
    camera: Path | None,
    calibration: Path | None,
    f: float | None,
    x0: float | None,
    y0: float | None,
    unit: ImageUnit | None,
    pixel_size: float | None,
    principal_point: str | None,
):
    """:func:`build_interior` from options that are None when not given (``X0GivenOpt``,
    ``Y0GivenOpt``, ``UnitGivenOpt``): the options the chosen camera source ignores are
    refused first (:func:`refuse_ignored_camera_options`), before any file is read; then the
    defaults apply (x0 = y0 = 0, unit mm)."""
    refuse_ignored_camera_options(
        camera=camera,
        calibration=calibration,
        f=f,
        x0=x0,
        y0=y0,
        unit=unit,
        pixel_size=pixel_size,
        principal_point=principal_point,
    )
    return build_interior(
        camera=camera,
        calibration=calibration,
        f=f,
        x0=0.0 if x0 is None else x0,
        y0=0.0 if y0 is None else y0,
        unit=ImageUnit.mm if unit is None else unit,
        pixel_size=pixel_size,
        principal_point=principal_point,
    )


def build_exterior(eo_text: str | None, angle_unit: AngleUnit, camera: Path | None = None):
    """The exterior orientation from ``--eo X0,Y0,Z0,omega,phi,kappa`` or the camera JSON."""
    from ..camera import ExteriorOrientation

    if eo_text is not None:
        v = split_numbers(eo_text, 6, "--eo X0,Y0,Z0,omega,phi,kappa")
        return ExteriorOrientation.from_degrees(*v, unit=AngleUnit(angle_unit).value)
    if camera is not None:
        _, eo = camera_from_json(camera)
        if eo is not None:
            return eo
    raise InputError("no exterior orientation: give --eo X0,Y0,Z0,omega,phi,kappa")


# --- shared option types ----------------------------------------------------------------------

CameraOpt = Annotated[
    Path | None,
    typer.Option(
        help="Camera JSON (interior and/or exterior orientation), or a calibration of another "
        "tool (interior only): Metashape XML or camera export (one sensor), OpenCV "
        "YAML/XML/JSON, COLMAP cameras.txt."
    ),
]
CalibrationOpt = Annotated[
    Path | None,
    typer.Option(
        help="Frame-camera calibration (pixels): Metashape XML or camera export (one sensor), "
        "camera JSON, OpenCV FileStorage YAML/XML/JSON or COLMAP cameras.txt (one camera); "
        "format by content."
    ),
]
FOpt = Annotated[float | None, typer.Option("--f", help="Principal distance (in --unit).")]
PixelSizeOpt = Annotated[
    float | None, typer.Option(help="Pixel size in mm (digital camera, mm <-> pixels).")
]
PPOpt = Annotated[
    str | None,
    typer.Option(
        help="Principal point COL,ROW in pixels (digital camera; top-left pixel centre = 0,0)."
    ),
]
#: ``--x0``/``--y0``/``--unit`` of this module's commands: None when not given, so that an
#: option the chosen camera source ignores is refused (:func:`refuse_ignored_camera_options`).
X0GivenOpt = Annotated[
    float | None, typer.Option("--x0", help="Principal point x0 (in --unit; default 0).")
]
Y0GivenOpt = Annotated[
    float | None, typer.Option("--y0", help="Principal point y0 (in --unit; default 0).")
]
UnitGivenOpt = Annotated[
    ImageUnit | None,
    typer.Option(help="Unit of f, x0, y0 and image coordinates (default mm).", show_default=False),
]
EOOpt = Annotated[
    str | None,
    typer.Option(
        "--eo", help="Exterior orientation X0,Y0,Z0,omega,phi,kappa (angles: --angle-unit)."
    ),
]
AngleOpt = Annotated[AngleUnit, typer.Option(help="Unit of angles on input and output.")]


# --- camera project ---------------------------------------------------------------------------


@app.command("project")
@options_in_errors(pixel_size="--pixel-size")
def project_cmd(
    points: Annotated[Path, typer.Argument(help="CSV of ground points (id,X,Y,Z).")],
    camera: CameraOpt = None,
    calibration: CalibrationOpt = None,
    f: FOpt = None,
    x0: X0GivenOpt = None,
    y0: Y0GivenOpt = None,
    unit: UnitGivenOpt = None,
    pixel_size: PixelSizeOpt = None,
    principal_point: PPOpt = None,
    eo: EOOpt = None,
    angle_unit: AngleOpt = AngleUnit.deg,
    cols: Annotated[
        str | None,
        typer.Option(
            "--cols",
            "--ground-cols",
            help="Ground coordinate columns (default X,Y,Z); --ground-cols is the same option "
            "(the name of orient resection and camera dlt estimate).",
        ),
    ] = None,
    pixel: Annotated[
        bool, typer.Option("--pixel", help="Output pixel (col, row) instead of image (x, y).")
    ] = False,
    behind: Annotated[
        Behind, typer.Option(help="Points behind the camera: stop with an error or write NaN.")
    ] = Behind.raise_,
    output: OutputCsvOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of CSV.")] = False,
) -> None:
    """Project ground points into an image with the collinearity equations.

    Image coordinates are right-handed (x right, y up) in the unit of the camera; with
    --pixel they are (col, row) with the top-left pixel's centre at (0, 0).
    """
    from ..camera import project
    from ..io import format_points_csv, read_points

    # the camera files are no destination (-o POINTS is: the points are read before it)
    check_outputs({"--camera": camera, "--calibration": calibration}, output=output)

    io = interior_from_options(
        camera=camera,
        calibration=calibration,
        f=f,
        x0=x0,
        y0=y0,
        unit=unit,
        pixel_size=pixel_size,
        principal_point=principal_point,
    )
    ext = build_exterior(eo, angle_unit, camera)
    with column_options(typed_option("--cols", "--ground-cols")):
        table = read_points(points, split_names(cols) or ["X", "Y", "Z"], auto_weights=False)
    xy = project(
        table.coords, io, ext, system="pixel" if pixel else "image", behind=Behind(behind).value
    )
    names = ["col", "row"] if pixel else ["x", "y"]
    if as_json:
        rows = [
            {"id": pid, names[0]: finite_or_none(p[0]), names[1]: finite_or_none(p[1])}
            for pid, p in zip(table.ids, xy)
        ]
        typer.echo(json_text({"unit": "px" if pixel else io.unit, "points": rows}), nl=False)
        return
    unit_txt = "px (top-left pixel centre = 0,0)" if pixel else f"{io.unit} (x right, y up)"
    text = format_points_csv(
        table.ids, xy, names, comments=[f"collinearity projection of {points}; {unit_txt}"]
    )
    emit_points(text, output, len(table.ids))


# --- camera convert ---------------------------------------------------------------------------


@app.command("convert")
def convert_cmd(
    source: Annotated[
        Path,
        typer.Argument(
            help="Calibration to read, format by content: Metashape XML or camera export "
            "(File > Export > Export Cameras; --sensor), camera JSON "
            "('bundle adjust --output-calibration', 'orient resection --output-params', ...), "
            "OpenCV FileStorage YAML/XML/JSON (camera_matrix, distortion_coefficients), COLMAP "
            "cameras.txt (one camera)."
        ),
    ],
    target: Annotated[
        Path,
        typer.Argument(
            help="File to write, format by suffix: .xml Metashape, .json photogeom camera "
            "(--camera), .yaml/.yml OpenCV FileStorage, .txt COLMAP cameras.txt."
        ),
    ],
    image_size: Annotated[
        str | None,
        typer.Option(
            "--image-size",
            help="WIDTHxHEIGHT in px (as --image-size of the bundle and grid commands; "
            "WIDTH,HEIGHT also read), for a camera JSON or OpenCV file that does not record "
            "the image size.",
            show_default=False,
        ),
    ] = None,
    sensor: Annotated[
        str | None,
        typer.Option(
            "--sensor",
            help="The sensor of a Metashape camera export (File > Export > Export Cameras) "
            "with several, by its id or label (id:ID or label:LABEL to match one of them).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Convert a frame-camera calibration between Metashape XML, camera JSON, OpenCV YAML and
    COLMAP cameras.txt.

    A Metashape camera export (File > Export > Export Cameras, Agisoft XML) gives the
    calibration of one sensor (--sensor when it has several): the adjusted one, else the
    initial one (with a warning). Standard deviations and the covariance (of a camera JSON
    written by 'bundle adjust --output-calibration', the <covariance> of a Metashape XML or
    camera export) are carried over where the target format has a place for them.
    """
    from ..camera.calibration_files import (
        calibration_format,
        calibration_text,
        read_calibration_source,
    )
    from .bundle import check_targets

    dst_fmt = calibration_format(target, "TARGET")
    check_targets(files=[("TARGET", target)])
    size = None
    if image_size is not None:
        w, h = image_size_option(image_size)
        if w <= 0 or h <= 0:
            raise InputError(f"--image-size {image_size}: give two whole numbers of pixels > 0")
        size = (w, h)
    from ..camera.metashape_export import CHOOSE_SENSOR

    try:
        cal, std, cov, read = read_calibration_source(source, size, sensor=sensor)
    except InputError as exc:  # an image size or sensor given for a file without them
        text = str(exc)
        if text.startswith("sensor "):
            text = "--sensor " + text.removeprefix("sensor ").replace(
                "leave the sensor out", "leave --sensor out"
            )
            raise InputError(text) from exc
        if size is None:
            raise
        text = text.replace("leave the image size out", "leave --image-size out")
        raise InputError(f"--image-size: {text}") from exc
    except FileFormatError as exc:
        text = str(exc).replace(CHOOSE_SENSOR, "choose one with --sensor ID or --sensor LABEL")
        text = text.replace("choose one by its id", "give --sensor its id")
        raise FileFormatError(text) from None
    text = calibration_text(cal, dst_fmt, std=std, covariance=cov)
    write_outputs([(target, text)])
    note = ""
    if read is not None:  # a Metashape camera export: which sensor and calibration
        note = f" from sensor {read.sensor_id} {read.label!r}"
        note += f" ({read.calibration_class} calibration)"
    say(f"wrote {target} ({dst_fmt}){note}", console())


# --- camera dlt estimate ----------------------------------------------------------------------


def load_control(
    points: Path,
    image: Path | None,
    *,
    ground_cols: str | None,
    image_cols: str | None,
    id_col: str | None,
    sigma_col: str | None = None,
    unmatched: dict | None = None,
):
    """Control points: ids, ground (n, 3), image (n, 2), check mask, per-point sigma or None.

    One CSV with both coordinate sets (default columns X,Y,Z and x,y), or a ground CSV and
    an image CSV joined by point id. A ``role`` column marks check points. With two files,
    the points found in both are used; ids found in only one (tie points of the image, ground
    points not measured) are left out and listed in ``unmatched`` (keys ``image_only``,
    ``ground_only``), which the caller reports.
    """
    from ..io import join_points, read_point_pairs, read_points

    gcols = split_names(ground_cols) or ["X", "Y", "Z"]
    icols = split_names(image_cols) or ["x", "y"]
    for option, names, n in (("--ground-cols", gcols, 3), ("--image-cols", icols, 2)):
        if len(names) != n:
            raise InputError(
                f"{option} {','.join(names)}: give {n} column names, comma-separated "
                f"(e.g. {'X,Y,Z' if n == 3 else 'x,y'})"
            )
    if image is None:
        with column_options("--image-cols", source="--image-cols", target="--ground-cols"):
            pairs = read_point_pairs(
                points, icols, gcols, id_column=id_col, sigma_column=sigma_col, auto_weights=False
            )
    else:
        with column_options("--ground-cols"):
            g = read_points(points, gcols, id_column=id_col, auto_weights=False)
        with column_options("--image-cols"):
            im = read_points(
                image, icols, id_column=id_col, sigma_column=sigma_col, auto_weights=False
            )
        pairs = join_points(im, g, allow_unmatched=True)
        if unmatched is not None:
            unmatched["image_only"] = list(pairs.unmatched_source)
            unmatched["ground_only"] = list(pairs.unmatched_target)
    sigma = None if pairs.weights is None else 1.0 / np.sqrt(pairs.weights)
    return pairs.ids, pairs.target, pairs.source, pairs.check_mask, sigma


def unmatched_text(unmatched: dict) -> str | None:
    """One line on the points left out of a ground/image join, or None."""
    parts = []
    if unmatched.get("image_only"):
        ids = unmatched["image_only"]
        parts.append(
            f"{len(ids)} image point(s) without ground coordinates (tie points), not used: "
            + _short_list(ids)
        )
    if unmatched.get("ground_only"):
        ids = unmatched["ground_only"]
        parts.append(
            f"{len(ids)} ground point(s) not measured in the image, not used: " + _short_list(ids)
        )
    return "; ".join(parts) if parts else None


def _short_list(ids, limit: int = 20) -> str:
    shown = ", ".join(ids[:limit])
    return shown + (f" ... ({len(ids)} in all)" if len(ids) > limit else "")


def say_unmatched(unmatched: dict, as_json: bool) -> None:
    """Report the points left out of the join on stderr (text output only)."""
    text = unmatched_text(unmatched)
    if text and not as_json:
        say(f"note: {text}", stderr=True)


@dlt_app.command("estimate")
@options_in_errors(sigma="--sigma")
def dlt_estimate(
    points: Annotated[
        Path, typer.Argument(help="CSV with ground X,Y,Z (and image x,y if IMAGE is not given).")
    ],
    image: Annotated[
        Path | None, typer.Argument(help="CSV with image x,y joined to POINTS by id.")
    ] = None,
    unit: Annotated[
        ImageUnit | None,
        typer.Option(
            help="Unit of f, x0, y0 and image coordinates (default mm; px with --pixel).",
            show_default=False,
        ),
    ] = None,
    pixel: Annotated[
        bool,
        typer.Option(
            "--pixel",
            help="Image coordinates are pixels col,row (top-left pixel centre = 0,0), as "
            "camera project --pixel writes them (default columns col,row): estimated in the "
            "right-handed x = col, y = -row (px); the camera written (--output-params) "
            "records that pixel system, so camera project --camera F --pixel gives col,row.",
        ),
    ] = False,
    constrained: Annotated[
        bool,
        typer.Option(help="Impose the two orthogonality conditions (>= 5 points)."),
    ] = False,
    linear: Annotated[
        bool, typer.Option(help="Linear solution only (no refinement of image residuals).")
    ] = False,
    ground_cols: Annotated[str | None, typer.Option(help="Ground columns (default X,Y,Z).")] = None,
    image_cols: Annotated[
        str | None, typer.Option(help="Image columns (default x,y; col,row with --pixel).")
    ] = None,
    id_col: IdColOpt = None,
    sigma_col: Annotated[
        str | None, typer.Option(help="Column of image standard deviations (unit of --unit).")
    ] = None,
    sigma_all: Annotated[
        float | None,
        typer.Option(
            "--sigma",
            help="Standard deviation of the image coordinates, in --unit, for every point "
            "(as orient resection --sigma; or per point with --sigma-col).",
        ),
    ] = None,
    check_ids: Annotated[
        str | None, typer.Option(help="Comma-separated ids of check points.")
    ] = None,
    alpha: AlphaOpt = None,
    angle_unit: AngleOpt = AngleUnit.deg,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON results.")] = False,
    report: ReportOpt = None,
    output_params: Annotated[
        Path | None,
        typer.Option(
            help="Write the parameters (the --json results, JSON) here, for 'camera dlt "
            "convert --params' and as --camera of 'camera project' and 'orient intersection'."
        ),
    ] = None,
    crs: Annotated[
        str | None,
        typer.Option(
            "--crs",
            help="CRS of the ground coordinates (EPSG code, WKT, PROJ string or enu:LAT,LON,H; "
            "default: the '# crs:' line of POINTS), recorded in the results; geographic CRSs "
            "(degrees) are refused.",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Estimate the 11 DLT parameters (and the orientations they imply) from control points.

    Image coordinates must be right-handed (x right, y up), or pixels col,row with --pixel.
    Prints L1..L11 with standard deviations, sigma0, the residuals (computed - observed) and
    the decomposed interior and exterior orientation.
    """
    from ..camera import estimate_dlt
    from ._common import file_crs

    check_outputs({"POINTS": points, "IMAGE": image}, report=report, output_params=output_params)
    alpha = check_alpha(alpha)
    if pixel and unit is not None and ImageUnit(unit).value != "px":
        raise InputError(
            f"--unit {ImageUnit(unit).value} with --pixel: pixel coordinates are in px (a DLT "
            "needs no pixel size); leave --unit out or give --unit px"
        )
    unit = ImageUnit.px if pixel else (unit or ImageUnit.mm)
    ground_crs = file_crs(crs, "--crs", points)
    unmatched: dict = {}
    ids, g, im, mask, sigma = load_control(
        points,
        image,
        ground_cols=ground_cols,
        image_cols=image_cols or ("col,row" if pixel else None),
        id_col=id_col,
        sigma_col=sigma_col,
        unmatched=unmatched,
    )
    if pixel:  # (col, row) -> the right-handed (x, y) = (col, -row) of the pixel system
        im = im * np.array([1.0, -1.0])
    say_unmatched(unmatched, as_json)
    if sigma_all is not None:
        if sigma is not None:
            raise InputError("give the image standard deviation once: --sigma or --sigma-col")
        sigma = np.full(len(ids), float(sigma_all))
    mask = check_mask(ids, mask, check_ids)
    g_ctrl, im_ctrl, kw = split_control(ids, g, im, mask)
    from ..errors import ReflectionError

    try:
        fit = estimate_dlt(
            g_ctrl,
            im_ctrl,
            constrained=constrained,
            refine=not linear,
            unit=ImageUnit(unit).value,
            sigma=None if sigma is None else sigma[~mask],
            **kw,
        )
    except ReflectionError as exc:  # the library's advice, and the option that does it
        if not pixel and exc.args and isinstance(exc.args[0], str):
            exc.args = (
                exc.args[0] + "; for pixel coordinates (col, row, as camera project --pixel "
                "writes them) give --pixel",
                *exc.args[1:],
            )
        raise
    fit = with_alpha(fit, alpha)  # the level of the residual table, JSON and report
    if ground_crs is not None:
        from dataclasses import replace

        # L1..L3, L5..L7 are image units per ground unit, L9..L11 per ground unit: the unit
        # of the ground CRS (e.g. US survey feet), not always metres
        gu = ground_crs.unit or "m"
        units = {
            k: (u[: -len("/m")] + f"/{gu}" if u.endswith("/m") else u)
            for k, u in fit.parameter_units.items()
        }
        fit = replace(fit, crs=ground_crs.text, parameter_units=units)
    au = AngleUnit(angle_unit).value
    gu = (ground_crs.unit if ground_crs is not None else None) or "m"  # of X0, Y0, Z0
    outputs: list[tuple[Path, str]] = []
    data = fit.to_dict()
    std = _dlt_std(fit, au)  # once: each is a propagation through the decomposition
    interior = fit.interior
    if pixel:  # image x = col, y = -row: the pixel system's origin is the image origin
        from dataclasses import replace as _replace

        interior = _replace(interior, origin_px=(0.0, 0.0))
        data["pixel"] = {
            "image_system": "x = col, y = -row (px; top-left pixel centre = 0,0)",
            "principal_point_px": [float(interior.x0), float(-interior.y0)],
        }
    data["orientation"] = _orientation_json(interior, fit.exterior, au, std)
    if unmatched:
        data["unmatched"] = unmatched
    if output_params is not None:
        outputs.append((output_params, json_text(data)))
    if report is not None:
        outputs.append((report, _dlt_report(fit, im_ctrl, kw.get("check_image"), au, std, gu)))
    write_outputs(outputs)
    if as_json:
        typer.echo(json_text(data), nl=False)
        return
    from ..report import print_fit

    out = console()
    print_fit(fit, console=out, angle_unit=au)
    out.print(
        _orientation_text(fit.interior, fit.exterior, au, std, gu),
        markup=False,
        highlight=False,
    )
    if pixel:
        out.print(
            "--pixel: estimated in x = col, y = -row (px); principal point col "
            f"{interior.x0:.6f}, row {-interior.y0:.6f} px",
            markup=False,
            highlight=False,
        )
    for path, _ in outputs:
        say(f"wrote {path}", out)


def _dlt_std(fit, au: str) -> tuple[dict, str]:
    """Standard deviations of the decomposed orientation (angles in ``au``): a posteriori,
    or a priori where the redundancy is 0; and which."""
    std = fit.orientation_std(au)
    if all(np.isfinite(v) for v in std.values()):
        return std, "a posteriori"
    return fit.orientation_std(au, prior=True), "a priori"


def _orientation_json(io, eo, au: str, std: tuple[dict, str] | None = None) -> dict:
    """Interior (with ``cx``, ``cy``) and exterior orientation (angles in ``au``) for JSON;
    with ``std`` their standard deviations (``std``, ``std_kind``)."""
    out = {"interior": io.to_dict(), "exterior": eo.to_dict(au), "cx": io.fx, "cy": io.fy}
    if std is not None:
        out["std"] = {k: (float(v) if np.isfinite(v) else None) for k, v in std[0].items()}
        out["std_kind"] = std[1]
    return out


def _orientation_text(
    io, eo, au: str, std: tuple[dict, str] | None = None, ground_unit: str | None = None
) -> str:
    a = eo.angles_in(au)
    gu = f" [{ground_unit}]" if ground_unit else ""
    text = (
        f"interior: cx = {io.fx:.6f}, cy = {io.fy:.6f}, x0 = {io.x0:.6f}, y0 = {io.y0:.6f}, "
        f"shear b2 = {io.b2:.3g} [{io.unit}]\n"
        f"exterior: X0 = {eo.X0:.4f}, Y0 = {eo.Y0:.4f}, Z0 = {eo.Z0:.4f}{gu}; "
        f"omega = {a[0]:.6f}, phi = {a[1]:.6f}, kappa = {a[2]:.6f} [{au}]"
    )
    if std is None:
        return text
    from ..report.format import fmt_std

    s, kind = std
    return text + (
        f"\nstd. dev. ({kind}): cx {fmt_std(s['cx'])}, cy {fmt_std(s['cy'])}, "
        f"x0 {fmt_std(s['x0'])}, y0 {fmt_std(s['y0'])}, b2 {fmt_std(s['b2'])} [{io.unit}]; "
        f"X0 {fmt_std(s['X0'])}, Y0 {fmt_std(s['Y0'])}, Z0 {fmt_std(s['Z0'])}{gu}; "
        f"omega {fmt_std(s['omega'])}, phi {fmt_std(s['phi'])}, kappa {fmt_std(s['kappa'])} "
        f"[{au}]"
    )


def _dlt_report(
    fit, image_ctrl, image_check, au: str, std: tuple[dict, str], ground_unit: str
) -> str:
    from ..report import Report

    rep = Report("DLT estimation", subtitle=fit.method)
    rep.add_fit(
        fit,
        title=f"DLT ({fit.method})",
        angle_unit=au,
        points=image_ctrl,
        check_points=image_check,
        point_labels=("x", "y"),
        point_unit=fit.residual_unit,
    )
    rep.add_text(
        "Decomposed orientation",
        # the ground unit of X0, Y0, Z0 as the console prints it
        _orientation_text(fit.interior, fit.exterior, au, std, ground_unit),
    )
    return rep.to_html()


# --- camera dlt convert -----------------------------------------------------------------------


@dlt_app.command("convert")
@options_in_errors(pixel_size="--pixel-size")
def dlt_convert(
    dlt: Annotated[
        str | None,
        typer.Option("--dlt", help="L1,...,L11: decompose into interior and exterior orientation."),
    ] = None,
    params: Annotated[
        Path | None,
        typer.Option(help="JSON with L1..L11 (e.g. from 'camera dlt estimate --output-params')."),
    ] = None,
    camera: CameraOpt = None,
    f: FOpt = None,
    x0: X0GivenOpt = None,
    y0: Y0GivenOpt = None,
    unit: UnitGivenOpt = None,
    eo: EOOpt = None,
    angle_unit: AngleOpt = AngleUnit.deg,
    as_json: JsonOpt = False,
) -> None:
    """Convert between the DLT and interior + exterior orientation.

    With --dlt or --params: L1..L11 -> (cx, cy, x0, y0, shear) and (X0, Y0, Z0, omega, phi,
    kappa). Otherwise the camera options (--f/--x0/--y0 or --camera, and --eo) -> L1..L11.
    """
    from ..camera import DLT, dlt_from_orientation, orientation_from_dlt
    from ..camera.dlt import NAMES

    au = AngleUnit(angle_unit).value
    u = "mm" if unit is None else ImageUnit(unit).value
    if dlt is not None or params is not None:
        if dlt is not None and params is not None:
            raise InputError("give the DLT once: --dlt or --params")
        source = "--dlt" if dlt is not None else "--params"
        camera_opts = {"--camera": camera, "--f": f, "--x0": x0, "--y0": y0, "--eo": eo}
        ignored = [name for name, v in camera_opts.items() if v is not None]
        if ignored:
            raise InputError(
                f"{', '.join(ignored)} cannot be used with {source}: {source} converts a DLT into "
                "interior and exterior orientation; the camera options give the other direction "
                "(orientation -> DLT) without --dlt/--params"
            )
        if dlt is not None:
            L = DLT(split_numbers(dlt, 11, "--dlt L1,...,L11"), u)
        else:
            data = read_parameters_json(params)
            try:
                L = DLT.from_dict(data)
            except InputError as exc:
                raise FileFormatError(f"{params}: {exc}") from None
            if unit is not None and L.unit != u:
                raise InputError(
                    f"--unit {u}: {params} records its DLT in {L.unit}; leave --unit out (the "
                    "file's unit is used)"
                )
        io, ext = orientation_from_dlt(L, unit=L.unit)
        if as_json:
            typer.echo(json_text(_orientation_json(io, ext, au)), nl=False)
        else:
            typer.echo(_orientation_text(io, ext, au))
        return
    io = interior_from_options(
        camera=camera,
        calibration=None,
        f=f,
        x0=x0,
        y0=y0,
        unit=unit,
        pixel_size=None,
        principal_point=None,
    )
    ext = build_exterior(eo, angle_unit, camera)
    L = dlt_from_orientation(io, ext)
    if as_json:
        typer.echo(json_text(DLT(L, io.unit).to_dict()), nl=False)
    else:
        typer.echo("\n".join(f"{n:<4} {v: .10g}" for n, v in zip(NAMES, L)))
