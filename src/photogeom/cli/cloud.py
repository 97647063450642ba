"""`photogeom cloud`: LAS/LAZ point clouds, chunk by chunk.

* ``info`` - the header: point count, format, scales/offsets, bounds, extra dimensions, CRS;
* ``transform`` - apply saved parameters (``transform estimate --output-params``,
  ``cloud register --output-params``) or a PROJ CRS change to a cloud, chunk by chunk;
* ``register`` - absolute orientation of one cloud to another from corresponding points
  (same count, same order), with check-pair statistics; Dask tasks (``--scheduler``).
"""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from ._common import (
    AngleUnit,
    JsonOpt,
    LogProgress,
    console,
    json_text,
    nan_to_none,
    options_in_errors,
    refuse_stdout_dash,
    say,
    scheduler_option,
    split_numbers,
    stage_spinner,
)

app = typer.Typer(
    help="LAS/LAZ point clouds chunk by chunk: info, transform, register (laspy; LAZ by lazrs).",
    no_args_is_help=True,
)

SchedulerOpt = Annotated[
    str,
    typer.Option(
        "--scheduler",
        help="Where the Dask tasks run: 'threads' (this process), 'local' or 'local:N' (a "
        "local cluster of N worker processes), 'sync', or a scheduler address "
        "tcp://host:8786.",
    ),
]


def _check_scheduler(scheduler: str | None) -> None:
    """Refuse a ``--scheduler`` value of a form photogeom does not take, naming the option
    (the library's message names its keyword ``scheduler``); nothing connects here."""
    if scheduler is not None:
        scheduler_option(scheduler)


class CloudMethod(str, Enum):
    """Absolute orientation methods that work from moments (out of core)."""

    svd = "svd"
    quaternion = "quaternion"
    dual_quaternion = "dual-quaternion"
    gauss_helmert = "gauss-helmert"


def _fmt3(v, fmt: str = ".6g") -> str:
    return ", ".join(f"{float(x):{fmt}}" for x in v)


@app.command("info")
def info(
    path: Annotated[Path, typer.Argument(help="LAS or LAZ file.")],
    json_out: JsonOpt = False,
    show_wkt: Annotated[bool, typer.Option("--wkt", help="Print the CRS as WKT.")] = False,
) -> None:
    """Describe a LAS/LAZ file from its header (no points are read)."""
    from ..io.cloud import cloud_info

    ci = cloud_info(path)
    units = _coordinate_units(ci)  # of scales, offsets, mins, maxs (X, Y, Z)
    if json_out:
        typer.echo(json_text({**ci.to_dict(), "units": units}), nl=False)
        return
    lines = [
        f"{ci.path}: {ci.point_count} points, LAS {ci.version}, point format {ci.point_format}"
        f"{', LAZ' if ci.compressed else ''}",
        "units   "
        + (
            "not recorded (no CRS)"
            if set(units.values()) == {NO_UNIT}
            else ", ".join(f"{k} {u}" for k, u in units.items())
        )
        + " (of scales, offsets, min, max)",
        f"scales  {_fmt3(ci.scales)}",
        f"offsets {_fmt3(ci.offsets)}",
        f"min     {_fmt3(ci.mins)}",
        f"max     {_fmt3(ci.maxs)}",
        f"dimensions: {', '.join(ci.dimensions)}",
        f"extra dimensions: {', '.join(ci.extra_dimensions) or 'none'}",
        f"CRS: {_crs_shown(ci)}",
        f"VLRs: {', '.join(ci.vlrs) or 'none'}",
    ]
    if show_wkt and ci.crs:
        lines.append(ci.crs)
    say("\n".join(lines))


@app.command("transform")
@options_in_errors(chunk_size="--chunk-size")
def transform(
    source: Annotated[Path, typer.Argument(help="Input LAS/LAZ.")],
    output: Annotated[Path, typer.Argument(help="Output LAS/LAZ (.laz: compressed).")],
    params: Annotated[
        Path | None,
        typer.Option(
            help="Parameter JSON (transform estimate / orient absolute / cloud register "
            "--output-params)."
        ),
    ] = None,
    from_crs: Annotated[
        str | None,
        typer.Option(
            "--from-crs",
            help="Source CRS of a PROJ transformation (default: the input's record; not with "
            "--params).",
        ),
    ] = None,
    to_crs: Annotated[
        str | None, typer.Option("--to-crs", help="Target CRS of a PROJ transformation.")
    ] = None,
    inverse: Annotated[
        bool,
        typer.Option(
            help="Apply the inverse of --params (not for --from-crs/--to-crs: swap them)."
        ),
    ] = False,
    crs: Annotated[
        str | None,
        typer.Option(
            "--crs",
            help="CRS to record in the output (default: --to-crs, else the target CRS of "
            "--params (its source CRS with --inverse); none when --params records the CRS of "
            "the input side only; else the input's record); refused when it contradicts "
            "--to-crs or the target CRS of --params.",
        ),
    ] = None,
    scales: Annotated[
        str | None,
        typer.Option(
            help="Output scales sx,sy,sz (default: the input's, carried into the unit of "
            "--to-crs when it changes: metres to degrees 0.01 -> 1e-7)."
        ),
    ] = None,
    chunk_size: Annotated[
        int, typer.Option(help="Points per chunk (memory is proportional to it).")
    ] = 1_000_000,
    allow_ballpark: Annotated[
        bool, typer.Option(help="Accept an approximate PROJ datum shift.")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress.")] = False,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="Run pieces of the file as Dask tasks: 'local', 'local:N', 'threads' or a "
            "scheduler address (default: in this process, chunk after chunk).",
        ),
    ] = None,
) -> None:
    """Transform a cloud with saved parameters (--params) or between CRSs (--from-crs,
    --to-crs), chunk by chunk; point format, extra dimensions, VLRs and the CRS record are
    kept, offsets recomputed; the output is written atomically."""
    from ..io.cloud import check_cloud_suffix, transform_cloud

    refuse_stdout_dash("OUTPUT", output, seekable=True)
    _check_scheduler(scheduler)
    if (params is None) == (to_crs is None):
        raise InputError("give either --params FILE or --from-crs and --to-crs")
    if params is not None and params.is_file() and output.is_file():
        import os

        if os.path.samefile(params, output):  # the cloud would replace its parameters
            raise InputError(
                f"OUTPUT {output} is the --params file: writing the cloud would replace the "
                "parameters it is transformed with; give another OUTPUT"
            )
    check_cloud_suffix(output, "OUTPUT")  # after the clash with --params, the more telling
    if inverse and params is None:
        raise InputError(
            "--inverse inverts the parameters of --params; a PROJ transformation (--to-crs) "
            "is inverted by swapping --from-crs and --to-crs"
        )
    if params is not None and from_crs is not None:
        raise InputError(
            "--from-crs belongs to a PROJ transformation (with --to-crs); with --params the "
            "parameter file names the CRS it transforms from (leave --from-crs out)"
        )
    if params is not None:
        from .transform import load_transform_record

        T, to_rec, from_rec, _, _ = load_transform_record(params)
        if inverse:
            T = T.inverse()
            to_rec, from_rec = from_rec, to_rec
        if from_rec is not None:
            _check_input_crs(source, from_rec, params, inverse)
        if crs is not None and to_rec is not None:
            _check_output_crs(crs, to_rec, f"the parameters of {params} transform to")
        if crs is None and to_rec is not None:
            crs = to_rec
        elif crs is None and from_rec is not None:
            # the file names the CRS of the input side only: the points leave it for a
            # system it does not name, and the input's record would mislabel them
            from ..io.cloud import NO_CRS

            crs = NO_CRS
    else:
        if crs is not None:
            _check_output_crs(crs, to_crs, "--to-crs says")
        from ..crs import ProjTransform
        from ..io.cloud import cloud_info

        info = cloud_info(source)
        src_crs = from_crs or info.crs
        if src_crs is None:
            if info.crs_error:
                raise InputError(
                    f"{source}: its CRS record cannot be read ({info.crs_error}): give the "
                    "CRS of its coordinates with --from-crs"
                )
            raise InputError(f"{source} records no CRS: give --from-crs")
        T = ProjTransform(src_crs, to_crs, allow_ballpark=allow_ballpark)
    sc = split_numbers(scales, 3, "--scales")
    progress = None
    if not quiet and not console(stderr=True).is_terminal:  # pipes and logs: plain lines
        bar = LogProgress("transforming")

        def progress(done: int, total: int) -> None:
            bar.update(f"transforming: {done:,} of {total:,} points")

        bar.start()
    elif not quiet:
        from rich.progress import Progress

        bar = Progress(transient=True)
        task = bar.add_task("transforming", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        bar.start()
    try:
        res = transform_cloud(
            source, output, T, chunk_size=chunk_size, scales=sc, crs=crs, progress=progress,
            scheduler=scheduler,
        )
    finally:
        if not quiet:
            bar.stop()
    say(
        f"wrote {res.point_count} points to {res.path} ({res.chunks} chunk(s), "
        f"{res.passes} pass(es)); scales {_fmt3(res.scales)}; offsets {_fmt3(res.offsets)}; "
        f"CRS {res.crs_name or 'none'}",
        stderr=True,
    )


def _check_output_crs(crs: str, target: str, says: str) -> None:
    """Refuse a ``--crs`` (the CRS recorded in the output) that is not the CRS the points are
    transformed to (``says`` names where that comes from)."""
    from ..crs import frame_from_text, parse_crs
    from ._common import same_crs

    if frame_from_text(crs) is None:
        parse_crs(crs, what="--crs")
    if not same_crs(crs, target):
        raise InputError(
            f"--crs {crs} would record another CRS than the one of the transformed points "
            f"({says} {target}): --crs names the CRS of the output coordinates, it does not "
            "convert them; leave --crs out"
        )


#: What ``cloud info`` says of a coordinate whose unit the file does not give.
NO_UNIT = "not recorded (no CRS axis for it)"


def _coordinate_units(ci) -> dict[str, str]:
    """The unit of X, Y and Z (scales, offsets, min, max of ``cloud info``) from the file's
    CRS record: its axes' units (``m``, ``ftUS``, ``deg``), :data:`NO_UNIT` for a coordinate
    without an axis (Z of a 2D CRS) or for all three without a readable record."""
    from ..crs import axis_units
    from ..errors import PhotogeomError

    units = []
    if ci.crs:
        try:
            units = axis_units(ci.crs)[:3]
        except PhotogeomError:
            units = []
    units += [NO_UNIT] * (3 - len(units))
    return dict(zip("XYZ", units))


def _crs_shown(ci) -> str:
    """The CRS line of ``cloud info``: its name, that none is recorded, or why the record
    cannot be read."""
    if ci.crs_name:
        return ci.crs_name
    if ci.crs_error:
        return f"a record that cannot be read ({ci.crs_error})"
    return "none recorded"


def _check_input_crs(source: Path, expected: str, params: Path, inverse: bool) -> None:
    """Refuse a cloud whose CRS record is not the one the parameters transform from."""
    from ..crs import parse_crs
    from ..io.cloud import cloud_info

    info = cloud_info(source)
    rec = info.crs
    if rec is None and info.crs_error:
        raise InputError(
            f"{source}: its CRS record cannot be read ({info.crs_error}), so it cannot be "
            f"checked against the {expected} that the parameters of {params} transform from: "
            "repair the record (e.g. write the cloud again with its CRS) before transforming"
        )
    if rec is not None and parse_crs(rec) != parse_crs(expected, what=f"{params}: crs"):
        raise InputError(
            f"{source} records the CRS {info.crs_name} but the parameters of "
            f"{params} transform from {expected}{' (--inverse)' if inverse else ''}: use the "
            "parameters of its CRS or transform it to that CRS first (--to-crs)"
        )


@app.command("register")
@options_in_errors(chunk_size="--chunk-size")
def register(
    source: Annotated[Path, typer.Argument(help="Cloud to orient (LAS/LAZ).")],
    target: Annotated[Path, typer.Argument(help="Reference cloud, same points in the same order.")],
    method: Annotated[CloudMethod, typer.Option(help="Direct method.")] = CloudMethod.svd,
    rigid: Annotated[
        bool, typer.Option("--rigid", help="Rigid transformation: scale fixed to 1.")
    ] = False,
    no_scale: Annotated[
        bool, typer.Option("--no-scale", hidden=True, help="Former name of --rigid.")
    ] = False,
    check_every: Annotated[
        int, typer.Option(help="Keep every k-th pair out as a check pair (0: none).")
    ] = 0,
    chunk_size: Annotated[int, typer.Option(help="Pairs per Dask task.")] = 1_000_000,
    scheduler: SchedulerOpt = "threads",
    output_params: Annotated[
        Path | None, typer.Option(help="Write the parameters (for cloud transform --params).")
    ] = None,
    angle_unit: Annotated[
        AngleUnit, typer.Option(help="Unit of the angles shown (the JSON keeps radians).")
    ] = AngleUnit.deg,
    report: Annotated[
        Path | None,
        typer.Option(help="Write an HTML report (parameters, statistics, check pairs)."),
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """Absolute orientation target ~ s R source + t of two clouds of corresponding points,
    out of core (one pass for the estimate, one for the check pairs), with sigma0 and the
    parameters' standard deviations from the moments. Lengths are in the unit of the target
    cloud's CRS (unlabelled when it records none)."""

    from ..distributed import register_clouds
    from ._common import write_outputs
    from .bundle import check_targets

    _check_scheduler(scheduler)
    if check_every < 0 or check_every == 1:
        raise InputError(f"--check-every {check_every}: give 0 (no check pairs) or k >= 2")
    check_targets(files=[("--output-params", output_params), ("--report", report)])
    with stage_spinner(f"registering {source.name} to {target.name}"):
        reg = register_clouds(
            source,
            target,
            method=method.value,
            with_scale=not (rigid or no_scale),
            check_every=check_every,
            chunk_size=chunk_size,
            scheduler=scheduler,
        )
    d = reg.to_dict()
    outputs: list[tuple[Path, str]] = []
    if output_params is not None:
        record = {"model_parameters": reg.fit.transform.to_dict()}
        record.update({"crs": reg.fit.crs, "source_crs": reg.fit.source_crs})
        outputs.append((output_params, json_text(record)))
    if report is not None:
        outputs.append((report, _register_report(reg, source, target, angle_unit.value)))
    write_outputs(outputs)
    if json_out:
        typer.echo(json_text(nan_to_none(d)), nl=False)
        return
    from ..report.format import parameter_rows

    f = reg.fit
    au = angle_unit.value
    # values and standard deviations with the digits of the report's parameter table
    # (each value to two digits beyond its standard deviation's first)
    shown = {name: (value, std) for name, value, std, _ in parameter_rows(f, au)}
    u = _length_unit(f.crs)
    ang = [shown[k] for k in ("omega", "phi", "kappa")]
    tr = [shown[k] for k in ("tx", "ty", "tz")]
    lines = [
        f"absolute orientation ({f.method}) of {reg.n_control} control pairs",
        "scale "
        + (" +- ".join(shown["scale"]) if "scale" in shown else f"{f.scale:.10f} (fixed)"),
        f"omega {ang[0][0]} {au}  phi {ang[1][0]} {au}  kappa {ang[2][0]} {au} (transposed "
        "convention)",
        f"  std. dev. {ang[0][1]} / {ang[1][1]} / {ang[2][1]} {au}",
        f"translation {', '.join(v for v, _ in tr)}{u}",
        f"  std. dev. {', '.join(s for _, s in tr)}{u}",
        f"sigma0 {f.sigma0:.4g}{u} (one target coordinate; redundancy {f.redundancy}; "
        "from the moments)",
        f"control RMSE {reg.control_rmse:.4g}{u} (per point, from the moments)",
        f"target CRS: {reg.crs_name or 'none recorded'}",
    ]
    if reg.n_check:
        lines.append(
            f"check pairs {reg.n_check}: RMSE {reg.check_rmse:.4g}{u}, per axis "
            f"{_fmt3(reg.check_rms, '.4g')}{u}, mean {_fmt3(reg.check_mean, '.4g')}{u}, max "
            f"{reg.check_max:.4g}{u} (residuals computed - observed)"
        )
    say("\n".join(lines))


def _register_report(reg, source: Path, target: Path, angle_unit: str) -> str:
    """The HTML report of ``cloud register``: the fit (parameters with standard deviations,
    sigma0; no per-point residuals out of core) and the check-pair statistics."""
    from ..report import Report

    unit = _length_unit(reg.fit.crs).strip()
    rep = Report("Registration of two point clouds", f"{source} -> {target}")
    rep.add_fit(reg.fit, title=f"Absolute orientation ({reg.fit.method})",
                angle_unit=angle_unit)
    u = f" [{unit}]" if unit else ""
    rows = [
        # sigma0 in the unit the console gives it (unweighted: one target coordinate's)
        [f"sigma0{u} (one target coordinate)", f"{reg.fit.sigma0:.4g}"],
        ["control pairs", f"{reg.n_control}"],
        [f"control RMSE{u} (per point)", f"{reg.control_rmse:.4g}"],
        ["check pairs", f"{reg.n_check}"],
    ]
    if reg.n_check:
        rows += [
            [f"check RMSE{u} (per point)", f"{reg.check_rmse:.4g}"],
            [f"check RMS X / Y / Z{u}", " / ".join(f"{v:.4g}" for v in reg.check_rms)],
            [f"check mean X / Y / Z{u}", " / ".join(f"{v:.4g}" for v in reg.check_mean)],
            [f"check max |v|{u}", f"{reg.check_max:.4g}"],
        ]
    rows.append(["target CRS", reg.crs_name or "none recorded"])
    rep.add_table(
        "Control and check pairs", ["quantity", "value"], rows,
        note="Residuals v = computed - observed; check pairs (every k-th pair, --check-every) "
        "are not in the estimate.",
    )
    return rep.to_html()


def _length_unit(crs: str | None) -> str:
    """`` UNIT`` of the lengths of a cloud in ``crs`` (its first axis), or ``""`` when it
    records none or PROJ cannot tell."""
    if not crs:
        return ""
    from ..crs import cartesian_crs
    from ..errors import PhotogeomError

    try:
        unit = cartesian_crs(crs, what="crs").unit
    except PhotogeomError:
        return ""
    return f" {unit}" if unit else ""
