"""`photogeom orient relative`: relative orientation of an image pair (see :mod:`.orient`).

Input: one CSV with the matched image coordinates of both images (``id,x1,y1,x2,y2``, or
``col1,row1,col2,row2`` with ``--pixel``), or two CSVs (``id,x,y`` each) joined by id.
Output: the five orientation elements with standard deviations, sigma0, the residual
y-parallaxes (RMS and the worst points), the points left out as wrong matches; ``--json``
for machines, ``--report`` for an HTML report with the parallax vectors drawn on the image
frame, ``--output`` for the model coordinates with their standard deviations.
"""

from __future__ import annotations

import os
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from .._lazy import LazyModule
from ..errors import InputError, PhotogeomError
from ._common import (
    AngleUnit,
    IdColOpt,
    alpha_help,
    check_alpha,
    check_outputs,
    column_options,
    console,
    json_text,
    options_in_errors,
    say,
    split_names,
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
)

np = LazyModule("numpy")  # imported when a command needs it: quick start-up

#: Largest ``--seed``: OpenCV's generator (``cv2.setRNGSeed``) takes a C int.
SEED_MAX = 2**31 - 1


class Method(str, Enum):
    """Parameterisations of the relative orientation."""

    dependent = "dependent"
    independent = "independent"


def register(app: typer.Typer) -> None:
    """Add this module's commands to the ``orient`` group."""
    app.command("relative")(relative)


def _read_matches(matches: Path, image2: Path | None, cols: str | None, pixel: bool, id_col):
    from ..io import read_points

    if image2 is None:
        names = split_names(cols) or (
            ["col1", "row1", "col2", "row2"] if pixel else ["x1", "y1", "x2", "y2"]
        )
        if len(names) != 4:
            raise InputError(
                f"--cols: expected 4 columns (image 1 x, y, image 2 x, y), got {names}"
            )
        kw = {"id_column": id_col, "role_column": None, "auto_weights": False}
        with column_options("--cols"):
            t1 = read_points(matches, names[:2], **kw)
            t2 = read_points(matches, names[2:], **kw)
        return list(t1.ids), t1.coords, t2.coords, []
    names = split_names(cols) or (["col", "row"] if pixel else ["x", "y"])
    if len(names) != 2:
        raise InputError(f"--cols: expected 2 columns per image file, got {names}")
    with column_options("--cols"):
        t1 = read_points(matches, names, id_column=id_col, role_column=None, auto_weights=False)
        t2 = read_points(image2, names, id_column=id_col, role_column=None, auto_weights=False)
    index2 = {p: k for k, p in enumerate(t2.ids)}
    ids = [p for p in t1.ids if p in index2]
    ids1 = set(t1.ids)
    only = [p for p in t1.ids if p not in index2] + [p for p in t2.ids if p not in ids1]
    if not ids:
        raise InputError(f"{matches} and {image2} share no point id")
    index1 = {p: k for k, p in enumerate(t1.ids)}
    k1 = [index1[p] for p in ids]
    return ids, t1.coords[k1], t2.coords[[index2[p] for p in ids]], only


@options_in_errors(
    sigma="--sigma", threshold="--threshold", pixel_size="--pixel-size", method="--method",
    seed="--seed", alpha="--alpha",
)
def relative(
    matches: Annotated[
        Path,
        typer.Argument(
            help="MATCHES.csv: id,x1,y1,x2,y2 (both images), or image 1's id,x,y if IMAGE2 is "
            "given."
        ),
    ],
    image2: Annotated[
        Path | None, typer.Argument(help="CSV with image 2's id,x,y, joined by id.")
    ] = None,
    camera: CameraOpt = None,
    calibration: CalibrationOpt = None,
    f: FOpt = None,
    x0: X0GivenOpt = None,
    y0: Y0GivenOpt = None,
    unit: UnitGivenOpt = None,
    pixel_size: PixelSizeOpt = None,
    principal_point: PPOpt = None,
    camera2: Annotated[
        Path | None,
        typer.Option(help="Camera JSON of image 2 when it differs (default: the same camera)."),
    ] = None,
    method: Annotated[
        Method, typer.Option(help="dependent (by, bz, omega2, phi2, kappa2) or independent.")
    ] = Method.dependent,
    pixel: Annotated[
        bool,
        typer.Option(
            "--pixel", help="Image coordinates are pixels col,row (top-left pixel centre = 0,0)."
        ),
    ] = False,
    cols: Annotated[
        str | None,
        typer.Option(help="Coordinate columns (default x1,y1,x2,y2; x,y with IMAGE2)."),
    ] = None,
    id_col: IdColOpt = None,
    sigma: Annotated[
        float | None,
        typer.Option(help="A-priori standard deviation of the image coordinates (image unit)."),
    ] = None,
    threshold: Annotated[
        float | None,
        typer.Option(help="RANSAC threshold, distance to the epipolar line (image unit)."),
    ] = None,
    robust: Annotated[
        bool,
        typer.Option(
            "--robust/--no-robust",
            help="Remove wrong matches (RANSAC start, data snooping); --no-robust keeps all.",
        ),
    ] = True,
    alpha: Annotated[
        float | None,
        typer.Option(
            help=alpha_help(
                "point's test (w-test with --sigma, else the tau-test)",
                uses="data snooping removes, and the tables, --json and --report flag, at it",
            ),
            show_default=False,
        ),
    ] = None,
    seed: Annotated[
        int,
        typer.Option(
            min=0,
            max=SEED_MAX,
            help="Random seed of the RANSAC start (same seed, same result), an integer in "
            f"0..{SEED_MAX}.",
        ),
    ] = 0,
    worst: Annotated[
        int, typer.Option(min=0, help="Number of worst y-parallaxes listed (>= 0).")
    ] = 10,
    angle_unit: AngleOpt = AngleUnit.deg,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON results.")] = False,
    report: Annotated[
        Path | None,
        typer.Option(help="Write an HTML report with the y-parallax vectors on the image frame."),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option(
            "--output",
            "-o",
            help="Write the model coordinates with their standard deviations (CSV) to this "
            "file (default: not written; the summary goes to stdout).",
        ),
    ] = None,
    output_cameras: Annotated[
        tuple[Path, Path] | None,
        typer.Option(
            "--output-cameras",
            metavar="CAM1.json CAM2.json",
            help="Write the two cameras in the model system (interior and exterior "
            "orientation, model unit), as orient intersection --camera and camera project "
            "--camera read them.",
        ),
    ] = None,
) -> None:
    """Relative orientation of an image pair from >= 5 matched points (coplanarity condition).

    Start values from the essential matrix (five-point RANSAC), then a Gauss-Helmert
    adjustment with data snooping. Prints the orientation elements with standard deviations,
    sigma0, residual y-parallaxes (RMS, worst points) and the points left out as wrong
    matches; --output writes the model coordinates (model unit: bx for --method dependent,
    the base length for independent) with their standard deviations, --output-cameras the
    two cameras in the model system.
    """
    from ..io import format_points_csv
    from ..orientation.relative import relative_orientation

    inputs = {"MATCHES": matches, "IMAGE2": image2, "--camera": camera, "--camera2": camera2,
              "--calibration": calibration}  # fmt: skip
    if output_cameras is None:
        check_outputs(inputs, report=report, output=output)
    else:  # each camera file against the inputs and the other options, then the two
        for path in output_cameras:
            check_outputs(inputs, report=report, output=output, output_cameras=path)
        one, two = (os.path.normcase(os.path.realpath(p)) for p in output_cameras)
        if one == two:
            raise InputError("--output-cameras: give two different files, image 1's first")
    alpha = check_alpha(alpha)  # before any file is read, as the other commands

    io1 = interior_from_options(
        camera=camera,
        calibration=calibration,
        f=f,
        x0=x0,
        y0=y0,
        unit=unit,
        pixel_size=pixel_size,
        principal_point=principal_point,
    )
    io2 = io1
    if camera2 is not None:
        io2, _ = camera_from_json(camera2)
        if io2 is None:
            raise InputError(f"--camera2 {camera2}: holds no interior orientation")
    source = f"{matches}{' + ' + str(image2) if image2 else ''}"  # what was oriented
    ids, xy1, xy2, unmatched = _read_matches(matches, image2, cols, pixel, id_col)
    if pixel:
        xy1, xy2 = io1.pixel_to_image(xy1), io2.pixel_to_image(xy2)
    try:
        fit = relative_orientation(
            xy1,
            xy2,
            io1,
            io2,
            method=Method(method).value,
            sigma=sigma,
            ids=ids,
            robust=robust,
            threshold=threshold,
            seed=seed,
            alpha=alpha,
        )
    except PhotogeomError as exc:
        raise _without_start_values(exc) from None
    au = AngleUnit(angle_unit).value
    model_unit = "bx" if fit.pair.method == "dependent" else "the base length"
    par = fit.parallax_report(worst=worst)
    mp = fit.model_points()
    std = mp.std if np.isfinite(fit.sigma0) else np.sqrt(np.einsum("nii->ni", mp.covariance_prior))
    outputs: list[tuple[Path, str]] = []
    if output is not None:
        outputs.append(
            (
                output,
                format_points_csv(
                    list(mp.ids),
                    np.column_stack([mp.points, std]),
                    ["X", "Y", "Z", "sX", "sY", "sZ"],
                    comments=[
                        f"model coordinates of the {fit.pair.method} relative orientation of "
                        f"{source}",
                        f"model unit: {model_unit}",
                        "sX, sY, sZ include the uncertainty of the orientation",
                    ],
                ),
            )
        )
    if output_cameras is not None:
        for k, (path, io, eo) in enumerate(
            zip(output_cameras, (io1, io2), (fit.exterior1, fit.exterior2)), start=1
        ):
            outputs.append(
                (
                    path,
                    json_text(
                        {
                            "system": f"model system of the {fit.pair.method} relative "
                            f"orientation of {source}",
                            "image": k,
                            "model_unit": model_unit,
                            "interior": io.to_dict(),
                            "exterior": eo.to_dict(au),
                        }
                    ),
                )
            )
    if report is not None:
        outputs.append((report, _report(fit, par, xy1, au, matches)))
    notes = []
    if unmatched:
        notes.append(f"ids in only one file, left out: {', '.join(unmatched[:30])}")
    write_outputs(outputs)
    if as_json:
        data = fit.to_dict()
        for k in ("ideal_observations", "observations", "epipolar_normal1"):
            data.get("extras", {}).pop(k, None)
        data["model_parameters"] = fit.pair.to_dict(au)
        data["parallax"] = par.to_dict()
        data["flagged"] = [i for i, b in zip(fit.all_ids, fit.flagged) if b]
        data["notes"] = data["notes"] + notes
        typer.echo(json_text(data), nl=False)
        return
    from ..report import print_fit

    out = console()
    if not out.is_terminal:  # the residual table has four columns and their tests
        from rich.console import Console

        out = Console(width=max(out.width, 170))
    say(
        f"relative orientation: {source}; "
        f"{len(ids)} matched point(s); image unit {io1.unit}",
        out,
    )
    print_fit(fit, console=out, angle_unit=au)
    say(par.text(), out)
    for line in _model_lines(fit, au):
        say(line, out)
    for n in notes:
        say(f"note: {n}", out)
    for path, _ in outputs:
        say(f"wrote {path}", out)


def _model_lines(fit, au: str) -> list[str]:
    """The orientations of both images in the model system, one line each (the console
    and the report print the same)."""
    lines = []
    for e, name in ((fit.exterior1, "image 1"), (fit.exterior2, "image 2")):
        a = e.angles_in(au)
        lines.append(
            f"{name} in the model system: X0 {e.X0:.6g}, Y0 {e.Y0:.6g}, Z0 {e.Z0:.6g}, "
            f"omega {a[0]:.6g}, phi {a[1]:.6g}, kappa {a[2]:.6g} {au}"
        )
    return lines


def _report(fit, par, xy1, au: str, source: Path) -> str:
    from ..report import Report

    rep = Report("Relative orientation", subtitle=str(source))
    rep.add_fit(
        fit,
        title=f"Relative orientation ({fit.method})",
        angle_unit=au,
        description="Residuals are the corrections of the image coordinates x1, y1, x2, y2 "
        "(adjusted minus observed) of the points used.",
    )
    rep.add_figure(
        "Residual y-parallaxes on image 1",
        _parallax_figure(fit, xy1),
        caption="Arrows: the y-parallax of each point used, drawn across its epipolar line "
        "(py times the line's unit normal; in the normal case (0, y1 - y2)). Crosses: points "
        "left out as wrong matches (their y-parallaxes are in the table below).",
    )
    rows = [
        [
            par.ids[k],
            f"{par.parallax[k]:.5g}",
            # the rounding of the printed table (ParallaxReport.text) and of the residual
            # table's w and tau columns
            f"{par.statistic[k]:.2f}" if np.isfinite(par.statistic[k]) else "-",
            "used" if par.used[k] else "left out",
        ]
        for k in par.worst
    ]
    rep.add_table(
        f"Worst y-parallaxes (RMS {par.rms:.4g} {par.unit} over the points used)",
        ["id", f"py [{par.unit}]", par.test, "status"],
        rows,
        note=f"critical value of the {par.test}-test: {par.critical_value:.3f}",
    )
    rep.add_text(
        "Orientations in the model system",
        "\n\n".join(_model_lines(fit, au))
        + f"\n\nX0, Y0, Z0 in the unit of the model system (see the notes above); angles in {au}.",
        pre=False,
    )
    return rep.to_html()


def _parallax_figure(fit, xy1):
    """Image 1 frame with the y-parallax vectors of the points used and the points left out."""
    from matplotlib.figure import Figure

    from ..report.plots import CLIPPED_COLOUR, arrow_scale, plain

    used = np.asarray(fit.inliers)
    vec = fit.parallax[:, None] * np.nan_to_num(fit.extras["epipolar_normal1"])
    ids = list(fit.all_ids)
    extent = float(np.ptp(xy1, axis=0).max()) or 1.0
    p, v = xy1[used], vec[used]
    # the scale follows the 90th percentile of the lengths (at most 7.5 % of the extent, the
    # longest drawn arrow 15 %): a few large parallaxes are drawn clipped, in orange
    sc = arrow_scale(v, 0.5 * extent)
    factor, unit = sc.factor, fit.residual_unit
    v = sc.drawn(v)
    shown = sc.shown & ~sc.clipped
    n_shown, n_used = int(sc.shown.sum()), int(used.sum())
    fig = Figure(figsize=(6.4, 5.6), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    count = f"{n_shown} of {n_used} shown" if n_shown < n_used else f"{n_used}"
    ax.plot(p[sc.shown, 0], p[sc.shown, 1], "o", color="#1f5fa8", ms=4 if n_shown == n_used
            else 2, label=f"used ({count})")  # fmt: skip
    q = sc.quiver(ax, p, v, shown, color="#1f5fa8", width=0.005)
    notes = []
    if sc.clipped.any():
        k = int(sc.clipped.sum())
        c = sc.clipped & sc.shown
        sc.quiver(ax, p, v, c, color=CLIPPED_COLOUR, width=0.005,
                  label=f"longer than {sc.clip:.3g} {unit}, clipped ({k})")  # fmt: skip
        notes.append(f"{k} longer than {sc.clip:.3g} {unit} drawn clipped (orange)")
    if n_shown < n_used:
        notes.append(f"arrows: {n_shown} of {n_used} shown (the longest and a random sample)")
    if sc.key > 0:
        key = sc.key
        ax.quiverkey(q, X=0.76, Y=1.035, U=key, label=f"{key:g} {unit}",
                     labelpos="E", coordinates="axes", color="black")  # fmt: skip
    if (~used).any():
        o = xy1[~used]
        ax.plot(o[:, 0], o[:, 1], "x", color="#c0392b", ms=7, label=f"left out ({len(o)})")
        for (x, y), t in zip(o, (i for i, u in zip(ids, used) if not u)):
            ax.annotate(plain(t), (x, y), textcoords="offset points", xytext=(5, 5), fontsize=8,
                        color="#c0392b")  # fmt: skip
    pad = 0.15 * extent
    lo, hi = xy1.min(axis=0), xy1.max(axis=0)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel(f"x1 [{fit.residual_unit}]")
    ax.set_ylabel(f"y1 [{fit.residual_unit}]")
    ax.grid(True, color="#dddddd", lw=0.6)
    ax.legend(loc="lower right", fontsize=8, framealpha=0.8)
    ex = f"{factor:,.0f}" if factor >= 10 else f"{factor:.3g}"
    ax.set_title(
        "\n".join([*notes, f"residual y-parallaxes, arrows x{ex}"]), fontsize=9.5, loc="left"
    )
    fig.tight_layout()
    return fig


def _without_start_values(exc):
    """``exc`` with the library's advice to pass start values (``initial=``), which the
    command has no option for, pointing to the Python function that takes them."""
    if exc.args and isinstance(exc.args[0], str) and "(initial=)" in exc.args[0]:
        exc.args = (
            exc.args[0]
            .replace(" or pass start values (initial=)", "")
            .replace(" start from better values (initial=) or", "")
            + " (start values: photogeom.relative_orientation(..., initial=) in Python; the "
            "command has no option for them)",
            *exc.args[1:],
        )
    return exc
