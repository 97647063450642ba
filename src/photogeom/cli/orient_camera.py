"""Commands of `photogeom orient` for frame cameras (see :mod:`.orient`).

* ``orient resection``: exterior orientation of one image from control points (closed-form
  start, collinearity adjustment, optional self-calibration), with statistics, image
  residuals and an HTML report with residual vectors;
* ``orient intersection``: object points from their image coordinates in >= 2 oriented
  images, with per-point standard deviations.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._lazy import LazyModule
from ..errors import InputError
from ._common import (
    CRS_FORMS,
    AlphaOpt,
    AngleUnit,
    IdColOpt,
    OutputCsvOpt,
    cartesian_crs_option,
    check_alpha,
    check_mask,
    check_outputs,
    column_options,
    console,
    file_crs,
    finite_or_none,
    json_text,
    options_in_errors,
    say,
    split_control,
    split_names,
    split_numbers,
    with_alpha,
    write_outputs,
)
from .camera import (
    AngleOpt,
    CalibrationOpt,
    CameraOpt,
    FOpt,
    PixelSizeOpt,
    PPOpt,
    UnitGivenOpt,
    X0GivenOpt,
    Y0GivenOpt,
    camera_from_json,
    interior_from_options,
    load_control,
    say_unmatched,
)

np = LazyModule("numpy")  # imported when a command needs it: quick start-up


def register(app: typer.Typer) -> None:
    """Add this module's commands to the ``orient`` group."""
    app.command("resection")(resection)
    app.command("intersection")(intersection)


@options_in_errors(sigma="--sigma", calibrate="--calibrate", pixel_size="--pixel-size")
def resection(
    points: Annotated[
        Path,
        typer.Argument(help="CSV with ground X,Y,Z (and image x,y if IMAGE is not given)."),
    ],
    image: Annotated[
        Path | None, typer.Argument(help="CSV with the image coordinates, joined by id.")
    ] = None,
    camera: CameraOpt = None,
    calibration: CalibrationOpt = None,
    f: FOpt = None,
    x0: X0GivenOpt = None,
    y0: Y0GivenOpt = None,
    unit: UnitGivenOpt = None,
    pixel_size: PixelSizeOpt = None,
    principal_point: PPOpt = None,
    pixel: Annotated[
        bool,
        typer.Option(
            "--pixel", help="Image coordinates are pixels col,row (top-left pixel centre = 0,0)."
        ),
    ] = False,
    calibrate: Annotated[
        str | None,
        typer.Option(help="Interior parameters to self-calibrate, e.g. f,x0,y0 or f,k1,k2."),
    ] = None,
    initial: Annotated[
        str | None,
        typer.Option(help="Start values X0,Y0,Z0,omega,phi,kappa (needed with 3 points)."),
    ] = None,
    sigma: Annotated[
        float | None,
        typer.Option(
            help="Standard deviation of the image coordinates, in --unit (mm by default; with "
            "--pixel too, as pixels are converted to --unit)."
        ),
    ] = None,
    sigma_col: Annotated[
        str | None,
        typer.Option(
            help="Column of per-point image standard deviations, in --unit like --sigma (also "
            "with --pixel: not pixels)."
        ),
    ] = None,
    ground_cols: Annotated[str | None, typer.Option(help="Ground columns (default X,Y,Z).")] = None,
    image_cols: Annotated[
        str | None, typer.Option(help="Image columns (default x,y; col,row with --pixel).")
    ] = None,
    id_col: IdColOpt = None,
    check_ids: Annotated[
        str | None, typer.Option(help="Comma-separated ids of check points.")
    ] = None,
    alpha: AlphaOpt = None,
    angle_unit: AngleOpt = AngleUnit.deg,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON results.")] = False,
    report: Annotated[
        Path | None, typer.Option(help="Write an HTML report with image residual vectors.")
    ] = None,
    output_params: Annotated[
        Path | None,
        typer.Option(help="Write the oriented camera (JSON, for 'orient intersection') here."),
    ] = None,
    crs: Annotated[
        str | None,
        typer.Option(
            "--crs",
            help=f"CRS of the ground coordinates ({CRS_FORMS}; default: the '# crs:' line of "
            "POINTS): recorded in the results and the camera JSON (and so in 'orient "
            "intersection' output); geographic CRSs (degrees) are refused.",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Space resection: exterior orientation of one image from >= 3 control points.

    Start values come from a closed-form P3P solution (or DLT); the collinearity equations
    are then adjusted. Prints X0, Y0, Z0, omega, phi, kappa (and calibrated interior
    parameters) with standard deviations, sigma0, and image residuals v = computed - observed.
    """
    from ..camera import ExteriorOrientation
    from ..orientation.resection import space_resection

    inputs = {"POINTS": points, "IMAGE": image, "--camera": camera, "--calibration": calibration}
    check_outputs(inputs, report=report, output_params=output_params)
    alpha = check_alpha(alpha)

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
    ground_crs = file_crs(crs, "--crs", points)
    unmatched: dict = {}
    ids, g, im, mask, sig = load_control(
        points,
        image,
        ground_cols=ground_cols,
        image_cols=image_cols or ("col,row" if pixel else None),
        id_col=id_col,
        sigma_col=sigma_col,
        unmatched=unmatched,
    )
    say_unmatched(unmatched, as_json)
    if pixel:
        im = io.pixel_to_image(im)
    if sigma is not None:
        if sig is not None:
            raise InputError("give the image standard deviation once: --sigma or --sigma-col")
        sig = np.full(len(ids), float(sigma))
    mask = check_mask(ids, mask, check_ids)
    g_ctrl, im_ctrl, kw = split_control(ids, g, im, mask)
    au = AngleUnit(angle_unit).value
    start = None
    if initial is not None:
        start = ExteriorOrientation.from_degrees(*split_numbers(initial, 6, "--initial"), unit=au)
    fit = space_resection(
        g_ctrl,
        im_ctrl,
        io,
        initial=start,
        calibrate=tuple(split_names(calibrate) or ()),
        sigma=None if sig is None else sig[~mask],
        **kw,
    )
    fit = with_alpha(fit, alpha)  # the level of the residual table, JSON and report
    if ground_crs is not None:
        from dataclasses import replace

        # the projection centre and its standard deviations are in the unit of the ground
        # coordinates, which the CRS names (e.g. US survey feet), not always metres
        units = dict(fit.parameter_units)
        if ground_crs.unit:
            units.update(dict.fromkeys(("X0", "Y0", "Z0"), ground_crs.unit))
        fit = replace(fit, crs=ground_crs.text, parameter_units=units)
    data = fit.to_dict()
    data["model_parameters"] = fit.camera.to_dict(au)
    if unmatched:
        data["unmatched"] = unmatched
    outputs: list[tuple[Path, str]] = []
    if output_params is not None:
        outputs.append((output_params, json_text(data)))
    if report is not None:
        outputs.append(
            (report, _resection_report(fit, im_ctrl, kw.get("check_image"), au, points))
        )
    write_outputs(outputs)
    if as_json:
        typer.echo(json_text(data), nl=False)
        return
    from ..report import print_fit

    out = console()
    say(
        f"space resection: {points}{' + ' + str(image) if image else ''}; "
        f"{len(im_ctrl)} control, {int(mask.sum())} check point(s); image unit {io.unit}",
        out,
    )
    print_fit(fit, console=out, angle_unit=au)
    for path, _ in outputs:
        say(f"wrote {path}", out)


def _resection_report(fit, image_ctrl, image_check, au: str, source: Path) -> str:
    from ..report import Report

    rep = Report("Space resection", subtitle=str(source))
    rep.add_fit(
        fit,
        title=f"Exterior orientation ({fit.method})",
        angle_unit=au,
        points=image_ctrl,
        check_points=image_check,
        point_labels=("x", "y"),
        point_unit=fit.residual_unit,
        description="Image residual vectors v = computed - observed at the image positions of "
        "the control points (image system: x right, y up).",
    )
    return rep.to_html()


@options_in_errors(sigma="--sigma")
def intersection(
    images: Annotated[
        list[Path],
        typer.Argument(help="One CSV of image coordinates (id,x,y) per image, >= 2 images."),
    ],
    camera: Annotated[
        list[Path],
        typer.Option(
            "--camera",
            help="Camera JSON per image, in the order of IMAGES (e.g. from 'orient resection "
            "--output-params'); repeat the option, once per image.",
            metavar="<path>",
        ),
    ],
    pixel: Annotated[
        bool, typer.Option("--pixel", help="Image coordinates are pixels col,row.")
    ] = False,
    image_cols: Annotated[
        str | None, typer.Option(help="Image columns (default x,y; col,row with --pixel).")
    ] = None,
    id_col: IdColOpt = None,
    sigma: Annotated[
        float | None,
        typer.Option(
            help="A-priori standard deviation of the image coordinates, in the image unit of "
            "the cameras (e.g. mm; with --pixel too, as pixels are converted)."
        ),
    ] = None,
    output: OutputCsvOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON results.")] = False,
    report: Annotated[
        Path | None, typer.Option(help="Write an HTML report with image residual vectors.")
    ] = None,
    crs: Annotated[
        str | None,
        typer.Option(
            "--crs",
            help="CRS of the ground coordinates, recorded in the output (default: that of the "
            "camera files, 'orient resection --crs').",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Space intersection: object points from >= 2 oriented images (least squares, all rays).

    Points are joined by id across the image files; points seen in fewer than two images are
    left out and listed. The output has X, Y, Z, their a-posteriori standard deviations
    (sX, sY, sZ; a priori from --sigma when the redundancy is 0), the number of rays and
    sigma0.
    """
    from ..io import format_points_csv, read_points
    from ..orientation.intersection import space_intersection

    inputs = {f"IMAGES ({p})": p for p in images}
    inputs.update({f"--camera {p}": p for p in camera or ()})  # not replaced either
    check_outputs(inputs, report=report, output=output)

    if len(images) < 2:
        raise InputError("space intersection needs >= 2 image files")
    if len(camera) != len(images):
        raise InputError(
            f"{len(images)} image file(s) but {len(camera)} --camera file(s): give one camera "
            "per image, in the same order, repeating the option (--camera cam1.json --camera "
            "cam2.json)"
            + ("; a comma does not separate files" if any("," in str(c) for c in camera) else "")
        )
    ground_crs = _cameras_crs(camera, crs)
    cams = []
    for path in camera:
        io, eo = camera_from_json(path)
        if io is None or eo is None:
            raise InputError(
                f"--camera {path}: needs both interior and exterior orientation"
                + (
                    " (a calibration file gives the interior only: give a camera JSON with "
                    "'exterior', e.g. from orient resection --output-params)"
                    if eo is None
                    else ""
                )
            )
        cams.append((io, eo))
    cols = split_names(image_cols) or (["col", "row"] if pixel else ["x", "y"])
    with column_options("--image-cols"):
        tables = [read_points(p, cols, id_column=id_col, auto_weights=False) for p in images]
    order: dict[str, None] = {}
    for t in tables:
        order.update(dict.fromkeys(t.ids))
    all_ids = list(order)
    obs = np.full((len(images), len(all_ids), 2), np.nan)
    index = {pid: k for k, pid in enumerate(all_ids)}
    for i, (t, (io, _)) in enumerate(zip(tables, cams)):
        xy = io.pixel_to_image(t.coords) if pixel else t.coords
        obs[i, [index[p] for p in t.ids]] = xy
    rays = np.sum(np.all(np.isfinite(obs), axis=2), axis=0)
    keep = rays >= 2
    dropped = [p for p, k in zip(all_ids, keep) if not k]
    if not keep.any():
        raise InputError("no point id occurs in two or more image files")
    ids = [p for p, k in zip(all_ids, keep) if k]
    res = space_intersection(obs[:, keep], cams, sigma=sigma)
    std = np.where(res.redundancy[:, None] > 0, res.std, res.std_prior if sigma else np.nan)
    notes = []
    if dropped:
        notes.append(f"left out (seen in fewer than 2 images): {', '.join(dropped[:30])}")
    outputs: list[tuple[Path, str]] = []
    if as_json:
        pts = [
            {
                "id": pid,
                "X": float(p[0]),
                "Y": float(p[1]),
                "Z": float(p[2]),
                "std": [finite_or_none(s) for s in sd],
                "n_rays": int(k),
                "sigma0": finite_or_none(s0),
            }
            for pid, p, sd, k, s0 in zip(ids, res.points, std, res.n_rays, res.sigma0)
        ]
        units = {
            "X, Y, Z, std": "ground unit of the cameras (that of X0, Y0, Z0)",
            "image": cams[0][0].unit,
            "sigma0": "1 (a posteriori / a priori)",
        }
        typer.echo(
            json_text(
                {
                    "points": pts,
                    "units": units,
                    "notes": notes,
                    "residual_convention": "computed minus observed",
                    "crs": ground_crs,
                }
            ),
            nl=False,
        )
    else:
        text = format_points_csv(
            ids,
            np.column_stack([res.points, std]),
            ["X", "Y", "Z", "sX", "sY", "sZ"],
            extra={
                "n_rays": [int(k) for k in res.n_rays],
                "sigma0": [float(s) for s in res.sigma0],
            },
            comments=[
                f"space intersection of {', '.join(map(str, images))}",
                "X, Y, Z and sX, sY, sZ in the ground unit of the cameras (that of X0, Y0, Z0); "
                "sX, sY, sZ: a-posteriori standard deviations (a priori from --sigma where the "
                "redundancy is 0); sigma0: a posteriori / a priori, unitless",
                *([f"crs: {ground_crs}"] if ground_crs else []),
            ],
        )
        if output is None:
            typer.echo(text, nl=False)
        else:
            outputs.append((output, text))
    if report is not None:
        outputs.append(
            (report, _intersection_report(res, ids, images, obs[:, keep], cams, ground_crs))
        )
    write_outputs(outputs)
    err = console(stderr=True)
    for n in notes:
        say(f"note: {n}", err)
    if output is not None:
        say(f"wrote {len(ids)} point(s) to {output}", err)
    if report is not None:
        say(f"wrote {report}", err)


def _crs_label(crs: str) -> str:
    from ..crs import crs_label

    return crs_label(crs)


def _cameras_crs(camera: list[Path], crs: str | None) -> str | None:
    """The CRS of the ground coordinates: ``--crs`` or the one the camera files record
    (they must agree)."""
    from ._common import same_crs
    from .camera import read_json

    recorded = {}
    from ..camera.calibration_files import calibration_content_format
    from .camera import _is_foreign_calibration

    for path in camera:
        if _is_foreign_calibration(path, calibration_content_format):
            continue  # a calibration of another tool: no CRS (camera_from_json reads it)
        data = read_json(path)  # a pipe: read once, kept for camera_from_json
        value = data.get("crs") if isinstance(data, dict) else None
        if value is not None:
            recorded[str(path)] = str(value)
    texts = list(dict.fromkeys(recorded.values()))
    if len(texts) > 1 and not all(same_crs(texts[0], t) for t in texts[1:]):
        listing = "; ".join(f"{p}: {c}" for p, c in recorded.items())
        raise InputError(
            f"the --camera files record different CRSs ({listing}): orient the images in one "
            "ground system"
        )
    if crs is not None:
        info = cartesian_crs_option(crs, "--crs")
        if texts and not same_crs(texts[0], info.text):
            raise InputError(
                f"--crs {crs}: the --camera files record the CRS {texts[0]}; --crs names the CRS "
                "of the cameras' ground coordinates, it does not convert them"
            )
        return info.text
    if texts:
        return cartesian_crs_option(texts[0], "the CRS of the --camera files").text
    return None


def _intersection_report(res, ids, images, obs, cams, crs=None) -> str:
    from ..report import Report

    rep = Report("Space intersection", subtitle=", ".join(map(str, images)))
    rows = [
        [
            pid,
            f"{p[0]:.4f}",
            f"{p[1]:.4f}",
            f"{p[2]:.4f}",
            *(f"{s:.4g}" if np.isfinite(s) else "-" for s in sd),
            int(k),
            f"{s0:.4g}" if np.isfinite(s0) else "-",
        ]
        for pid, p, sd, k, s0 in zip(ids, res.points, res.std, res.n_rays, res.sigma0)
    ]
    # the unit of the ground CRS in the headings; without a CRS the cameras' ground unit is
    # not known by name (the note says so)
    unit = None
    if crs:
        from ..crs import cartesian_crs

        unit = cartesian_crs(crs, what="the ground CRS").unit
    u = f" [{unit}]" if unit else ""
    rep.add_table(
        "Object points",
        ["id", *(f"{c}{u}" for c in ("X", "Y", "Z", "sX", "sY", "sZ")), "rays", "sigma0"],
        rows,
        note="X, Y, Z and their standard deviations sX, sY, sZ in the ground unit of the "
        "cameras (that of X0, Y0, Z0); sigma0 a posteriori / a priori (unitless)."
        + (f" Ground CRS: {_crs_label(crs)}." if crs else ""),
    )
    for i, path in enumerate(images):
        ok = np.all(np.isfinite(obs[i]), axis=1)
        if not ok.any():
            continue
        rep.add_residual_plot(
            f"Image {i + 1} ({path}): residuals v = computed - observed",
            obs[i][ok],
            res.residuals[i][ok],
            ids=[p for p, k in zip(ids, ok) if k],
            unit=cams[i][0].unit,
            name="object points",  # intersected, neither control nor check points
        )
    return rep.to_html()
