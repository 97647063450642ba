"""`photogeom transform`: estimate and apply 2D/3D coordinate transformations.

``estimate`` fits a model to point pairs (one CSV holding both coordinate sets, or two CSVs
joined by point id) and prints parameters with standard deviations, the adjustment
statistics and the residuals (computed minus observed); ``apply`` transforms a point file
with saved parameters.
"""

from __future__ import annotations

from dataclasses import replace
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from .._lazy import LazyModule
from ..errors import FileFormatError, InputError
from ._common import (
    CRS_FORMS,
    AlphaOpt,
    AngleUnit,
    IdColOpt,
    cartesian_crs_option,
    check_alpha,
    check_mask,
    check_out_cols,
    check_outputs,
    column_options,
    console,
    crs_from_comments,
    dash_is_stdout,
    file_crs,
    json_text,
    load_pairs,
    options_in_errors,
    same_crs,
    say,
    split_names,
    with_alpha,
    write_outputs,
)
from ._stream import busy, run_point_job, single_threaded_blas

if TYPE_CHECKING:
    from ..io.points import PointPairs

np = LazyModule("numpy")  # imported when a command needs it: quick start-up

MODELS = (
    "similarity2d",
    "affine2d",
    "projective2d",
    "polynomial2d",
    "rigid3d",
    "similarity3d",
    "affine3d",
    "projective3d",
    "polynomial3d",
)

Model = Enum("Model", {m: m for m in MODELS}, type=str)


class ErrorsIn(str, Enum):
    """Which point set carries errors (projective models)."""

    target = "target"
    both = "both"


app = typer.Typer(
    help="Estimate and apply 2D/3D coordinate transformations.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


@app.command("estimate")
@options_in_errors(sigma0_prior="--sigma0-prior", order="--order", errors_in="--errors-in")
def estimate(
    model: Annotated[
        Model,
        typer.Argument(help="Transformation model.", case_sensitive=False, show_default=False),
    ],
    source: Annotated[
        Path,
        typer.Argument(
            help="CSV with the source points (and the target points if TARGET is not given)."
        ),
    ],
    target: Annotated[
        Path | None,
        typer.Argument(help="CSV with the target points, joined to SOURCE by point id."),
    ] = None,
    order: Annotated[
        int | None, typer.Option("--order", "-k", help="Polynomial order (polynomial models).")
    ] = None,
    source_cols: Annotated[
        str | None,
        typer.Option(help="Source coordinate columns, e.g. x,y or x2,y2 (default: found by name)."),
    ] = None,
    target_cols: Annotated[
        str | None,
        typer.Option(help="Target coordinate columns, e.g. X,Y,Z (default: found by name)."),
    ] = None,
    id_col: Annotated[
        str | None, typer.Option(help="Id column (default: id, point, point_id or name).")
    ] = None,
    check_ids: Annotated[
        str | None,
        typer.Option(
            help="Comma-separated ids of check points (default: rows whose role column says "
            "'check'). Check points do not enter the estimate."
        ),
    ] = None,
    weights_col: Annotated[
        str | None,
        typer.Option(help="Column of per-point weights (unitless; with two files: in TARGET)."),
    ] = None,
    sigma_col: Annotated[
        str | None,
        typer.Option(
            help="Column of per-point standard deviations (target units; weight "
            "sigma0_prior^2 / sigma^2, so that sigma0 is expected near --sigma0-prior)."
        ),
    ] = None,
    sigma0_prior: Annotated[
        float, typer.Option(help="A-priori standard deviation of unit weight.")
    ] = 1.0,
    unit: Annotated[
        str,
        typer.Option(
            help="Length unit of the target coordinates, labelling shifts, residuals and RMS "
            "(e.g. mm, m, px) [default: the --target-crs unit, else none].",
            show_default=False,
        ),
    ] = "",
    source_unit: Annotated[
        str,
        typer.Option(
            help="Unit of the source coordinates (default: px with --source-system pixel, else "
            "--unit); scale parameters are labelled target/source unit, e.g. mm/px."
        ),
    ] = "",
    source_system: Annotated[
        str | None,
        typer.Option(
            help="2D source system (pixel, image, fiducial, ...): handedness is fixed for you."
        ),
    ] = None,
    target_system: Annotated[
        str | None, typer.Option(help="2D target system (pixel, image, fiducial, ...).")
    ] = None,
    errors_in: Annotated[
        ErrorsIn,
        typer.Option(
            help="Projective models: errors in the target only (Gauss-Markov) or in both sets "
            "(Gauss-Helmert).",
        ),
    ] = ErrorsIn.target,
    allow_unmatched: Annotated[
        bool,
        typer.Option(
            help="With two files: leave out (and list) ids found in only one file instead of "
            "stopping with an error."
        ),
    ] = False,
    alpha: AlphaOpt = None,
    as_json: Annotated[
        bool,
        typer.Option("--json", help="Print machine-readable results (JSON) instead of tables."),
    ] = False,
    report: Annotated[
        Path | None, typer.Option(help="Write an HTML report with residual plots to this file.")
    ] = None,
    output_params: Annotated[
        Path | None,
        typer.Option(help="Write the estimated parameters (JSON, for 'transform apply') here."),
    ] = None,
    angle_unit: Annotated[
        AngleUnit,
        typer.Option(help="Unit of angles in the text output and report."),
    ] = AngleUnit.deg,
    source_crs: Annotated[
        str | None,
        typer.Option(
            help=f"CRS of the source coordinates, recorded in the results ({CRS_FORMS}; "
            "default with two files: SOURCE's '# crs:' line); geographic CRSs (degrees) are "
            "refused.",
            show_default=False,
        ),
    ] = None,
    target_crs: Annotated[
        str | None,
        typer.Option(
            help="CRS of the target coordinates (residuals, parameters), recorded in the "
            "results, the parameter file and the report; its unit labels the residuals "
            "(default: TARGET's '# crs:' line).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Estimate a transformation TARGET = T(SOURCE) from point pairs by least squares.

    Prints the parameters with standard deviations and units, sigma0 (a priori and
    a posteriori), the redundancy, the residuals v = computed - observed of control points
    with data-snooping statistics, and check-point residuals and RMSE.
    """
    from ..estimation import estimate_transform

    check_outputs({"SOURCE": source, "TARGET": target}, report=report, output_params=output_params)
    alpha = check_alpha(alpha)
    model = Model(model).value
    angle_unit = AngleUnit(angle_unit).value
    errors_in = ErrorsIn(errors_in).value
    dim = 3 if model.endswith("3d") else 2
    tcrs = file_crs(target_crs, "--target-crs", target, dim=dim, unit=unit)
    scrs = file_crs(
        source_crs,
        "--source-crs",
        source if target is not None else None,
        dim=dim,
        unit=None if source_system else source_unit,
    )
    if tcrs is not None and not unit and tcrs.unit:
        unit = tcrs.unit
    if scrs is not None and not source_unit and not source_system and scrs.unit:
        source_unit = scrs.unit
    with busy(f"reading {source.name}", source, target) as step:
        pairs = load_pairs(
            source,
            target,
            source_cols=source_cols,
            target_cols=target_cols,
            id_col=id_col,
            weights_col=weights_col,
            sigma_col=sigma_col,
            allow_unmatched=allow_unmatched,
        )
        _check_dimensions(model, pairs)
        _check_sigma_units(errors_in, pairs, unit, source_unit, source_system)
        mask = check_mask(pairs.ids, pairs.check_mask, check_ids, list_ids=True)
        step(f"estimating {model} from {len(pairs)} point pairs")
        fit = estimate_transform(
            model,
            pairs.source,
            pairs.target,
            order=order,
            # sigmas of a sigma column are standard deviations: weights s0^2 / sigma^2, as
            # the library's P = s0^2 Cll^-1 for a covariance
            weights=(
                pairs.weights * sigma0_prior**2
                if pairs.weights_from_sigma and pairs.weights is not None
                else pairs.weights
            ),
            check=mask,
            ids=pairs.ids,
            sigma0_prior=sigma0_prior,
            source_system=source_system,
            target_system=target_system,
            errors_in=errors_in,
            unit=unit,
            source_unit=source_unit,
        )
    if pairs.notes:
        fit = replace(fit, notes=tuple(fit.notes) + tuple(pairs.notes))
    fit = with_alpha(fit, alpha)
    if tcrs is not None or scrs is not None:
        fit = _with_crs(fit, tcrs, scrs, pairs)
    files = [str(source)] + ([str(target)] if target is not None else [])
    inputs = {
        "files": files,
        "source_columns": list(pairs.source_columns),
        "target_columns": list(pairs.target_columns),
        "n_control": int((~mask).sum()),
        "n_check": int(mask.sum()),
        "unmatched_source": list(pairs.unmatched_source),
        "unmatched_target": list(pairs.unmatched_target),
        # the units of both sides, for the '# unit:' line of 'transform apply' (None: not given)
        "unit": unit or None,
        "source_unit": _source_unit(unit, source_unit, source_system) or None,
    }

    params = fit.to_dict()

    # Build every output in memory first; files are then replaced atomically.
    outputs: list[tuple[Path, str]] = []
    if output_params is not None:  # with the input, so that apply names its columns
        outputs.append((output_params, json_text({**params, "input": inputs})))
    if report is not None:
        outputs.append((report, _report_html(fit, pairs, mask, inputs, model, angle_unit)))
    write_outputs(outputs)

    if as_json:
        typer.echo(json_text({**params, "input": inputs}), nl=False)
        return
    out = console()
    say(_input_line(inputs, model), out)
    from ..report import print_fit

    print_fit(fit, console=out, angle_unit=angle_unit)
    for path, _ in outputs:
        say(f"wrote {path}", out)


def _with_crs(fit, tcrs, scrs, pairs: PointPairs):
    """``fit`` recording the CRSs, with a note where map coordinates are used in 3D."""
    from ..crs import curvature_note

    notes = []
    for info, pts, side in ((scrs, pairs.source, "source"), (tcrs, pairs.target, "target")):
        note = None if info is None else curvature_note(info, pts, what=f"{side} coordinates")
        if note:
            notes.append(note)
    return replace(
        fit,
        crs=None if tcrs is None else tcrs.text,
        source_crs=None if scrs is None else scrs.text,
        notes=tuple(fit.notes) + tuple(notes),
    )


def _check_sigma_units(
    errors_in: str, pairs, unit: str, source_unit: str, source_system: str | None
) -> None:
    """With errors in both point sets a sigma column's standard deviations (target units)
    weigh the source coordinates too: refuse when the source is in another unit (its unit
    defaults to ``px`` with ``--source-system pixel``, else to ``--unit``)."""
    if errors_in != "both" or not pairs.weights_from_sigma:
        return
    src = _source_unit(unit, source_unit, source_system)
    if src.strip().lower() == (unit or "").strip().lower():
        return
    raise InputError(
        "--errors-in both with a sigma column: its standard deviations are in target units "
        f"({unit or 'unstated'}) and would be given to the source coordinates ({src}) as "
        "well; give relative weights in a weight column (--weights-col) instead, or state "
        "one unit for both point sets with --unit and --source-unit"
    )


def _check_dimensions(model: str, pairs: PointPairs) -> None:
    from ..estimation import MODELS as DIMS

    need = DIMS.get(model)
    for side, cols in (("source", pairs.source_columns), ("target", pairs.target_columns)):
        if need is not None and len(cols) != need:
            raise InputError(
                f"{model} works on {need}D points but the {side} columns are {','.join(cols)} "
                f"({len(cols)}D); choose {need} columns with --{side}-cols"
            )


def _source_unit(unit: str, source_unit: str, source_system: str | None) -> str:
    """The unit of the source coordinates as ``--source-unit`` documents it: the option, else
    ``px`` with ``--source-system pixel``, else ``--unit`` ("" when none is known)."""
    return source_unit or ("px" if (source_system or "").lower() == "pixel" else unit)


def _input_line(inputs: dict, model: str) -> str:
    files = " + ".join(inputs["files"])
    return (
        f"{model}: {files}; source {','.join(inputs['source_columns'])} -> target "
        f"{','.join(inputs['target_columns'])}; {inputs['n_control']} control, "
        f"{inputs['n_check']} check point(s)"
    )


#: Ids of points without a partner named in the report, per file, at most.
_SHOWN_IDS = 20


def _ids_shown(ids) -> str:
    """``ids`` for the report: at most :data:`_SHOWN_IDS`, then how many there are in all
    (as the note of the text output); "-" for none."""
    ids = list(ids)
    if not ids:
        return "-"
    more = f" ... ({len(ids)} in all)" if len(ids) > _SHOWN_IDS else ""
    return ", ".join(ids[:_SHOWN_IDS]) + more


def _report_html(fit, pairs: PointPairs, mask: np.ndarray, inputs: dict, model: str, angle_unit):
    from ..report import Report

    rep = Report(f"Transformation {model}", subtitle=" + ".join(inputs["files"]))
    rep.add_text(
        "Input",
        f"{len(pairs.ids)} point pair(s): {inputs['n_control']} control (in the estimate), "
        f"{inputs['n_check']} check (not in the estimate). Source columns "
        f"{', '.join(pairs.source_columns)}; target columns {', '.join(pairs.target_columns)}."
        + (
            f"\n\nLeft out (no partner in the other file): source only "
            f"{_ids_shown(pairs.unmatched_source)}; target only "
            f"{_ids_shown(pairs.unmatched_target)}"
            + (
                " (all in --json: input.unmatched_source, input.unmatched_target)."
                if max(len(pairs.unmatched_source), len(pairs.unmatched_target)) > _SHOWN_IDS
                else "."
            )
            if pairs.unmatched_source or pairs.unmatched_target
            else ""
        ),
        pre=False,
    )
    tcols = tuple(pairs.target_columns)
    y_down = len(tcols) >= 2 and tcols[1].lower() == "row"
    rep.add_fit(
        fit,
        title=f"{model} ({fit.method})",
        angle_unit=angle_unit,
        points=pairs.target[~mask][:, :2],
        check_points=pairs.target[mask][:, :2] if mask.any() else None,
        point_labels=(tcols[0], tcols[1]) if len(tcols) >= 2 else None,
        y_down=y_down,
    )
    return rep.to_html()


def load_transform_record(path: Path):
    """``(transformation, target CRS, source CRS, (source columns, target columns), (source
    unit, target unit))`` of a parameter JSON: the output of ``--output-params`` or
    ``--json`` of ``transform estimate``, or a bare ``Transform.to_dict()``; the CRSs, columns
    and units are None where the file records none (the columns and units are those of the
    estimate, in its ``input`` section; the target unit else its ``residual_unit``).

    Where the file records a row/y flip (``extras.handedness``, written by ``transform
    estimate`` for a left-handed system such as ``pixel`` paired with a right-handed one),
    the transformation is a :class:`HandedTransform` that applies the flips, so that it maps
    the source coordinates as given to the target coordinates as given (and its inverse
    back)."""
    from ..io.jsonfile import build_from_json, read_json_object
    from ..transforms import from_dict

    data = read_json_object(path)
    crs = {"crs": None, "source_crs": None}
    columns = _recorded_columns(data)
    units = _recorded_units(data)
    if isinstance(data, dict):
        for key in crs:
            value = data.get(key)
            if value is not None and not isinstance(value, str):
                raise FileFormatError(f"{path}: {key!r} must be a CRS text (e.g. EPSG:25832)")
            crs[key] = value
    flips = _handedness_flips(data, path)
    if isinstance(data, dict) and isinstance(data.get("model_parameters"), dict):
        data = data["model_parameters"]
    elif isinstance(data, dict) and isinstance(data.get("transform"), dict):
        data = data["transform"]
    if not isinstance(data, dict) or "model" not in data:
        raise FileFormatError(
            f"{path}: no transformation parameters found (expected the JSON written by "
            "'photogeom transform estimate --output-params')"
        )
    transform = build_from_json(from_dict, data, path, "transformation parameters")
    if any(flips):
        if getattr(transform, "dim", 2) != 2:
            raise FileFormatError(
                f"{path}: extras.handedness flips the row/y coordinate, which applies to 2D "
                f"transformations only, but the model is {transform.name}"
            )
        transform = HandedTransform(transform, *flips)
    return transform, crs["crs"], crs["source_crs"], columns, units


def _recorded_units(data) -> tuple[str | None, str | None]:
    """``(source unit, target unit)`` of a result JSON: ``input.source_unit`` and
    ``input.unit`` of ``transform estimate`` (and ``orient absolute``), the target unit else
    the fit's ``residual_unit`` (None where the file records none)."""
    if not isinstance(data, dict):
        return None, None
    inputs = data.get("input") if isinstance(data.get("input"), dict) else {}

    def text(value) -> str | None:
        return value.strip() if isinstance(value, str) and value.strip() else None

    target = text(inputs.get("unit")) if "unit" in inputs else text(data.get("residual_unit"))
    return text(inputs.get("source_unit")), target


def _recorded_columns(data) -> tuple[list[str] | None, list[str] | None]:
    """``(source columns, target columns)`` recorded in the ``input`` section of a result
    JSON of ``transform estimate`` (None where the file records none)."""
    inputs = data.get("input") if isinstance(data, dict) else None
    out: list[list[str] | None] = [None, None]
    if isinstance(inputs, dict):
        for k, key in enumerate(("source_columns", "target_columns")):
            names = inputs.get(key)
            if isinstance(names, list) and names and all(isinstance(c, str) for c in names):
                out[k] = names
    return out[0], out[1]


def _handedness_flips(data, path: Path) -> tuple[bool, bool]:
    """``(source_flip_y, target_flip_y)`` recorded in ``extras.handedness`` of a result JSON
    of ``transform estimate`` (both False where the file records none)."""
    extras = data.get("extras") if isinstance(data, dict) else None
    hand = extras.get("handedness") if isinstance(extras, dict) else None
    if hand is None:
        return False, False
    if not isinstance(hand, dict):
        raise FileFormatError(
            f"{path}: extras.handedness must be an object with source_flip_y and target_flip_y"
        )
    flips = []
    for key in ("source_flip_y", "target_flip_y"):
        value = hand.get(key, False)
        if not isinstance(value, bool):
            raise FileFormatError(f"{path}: extras.handedness.{key} must be true or false")
        flips.append(value)
    return flips[0], flips[1]


class HandedTransform:
    """A 2D transformation fitted between systems of opposite handedness, applied to the
    coordinates as given.

    ``transform estimate --source-system pixel --target-system fiducial`` (and the other
    mixed pairs) fits the model to ``(col, -row)`` of the left-handed side and records that
    in ``extras.handedness``; this wrapper negates the second input coordinate before the
    model (``flip_in``) and the second output coordinate after it (``flip_out``), so that
    :meth:`apply` maps the source points as given to the target points as given.

    Parameters
    ----------
    model : Transform
        The fitted model (working on the flipped coordinates).
    flip_in, flip_out : bool
        Negate the second coordinate of the input / of the output.
    """

    dim = 2

    def __init__(self, model, flip_in: bool, flip_out: bool) -> None:
        self.model = model
        self.flip_in = bool(flip_in)
        self.flip_out = bool(flip_out)
        self.name = model.name

    def apply(self, points) -> np.ndarray:
        """Transform points ``(n, 2)`` (or one point ``(2,)``) as given."""
        p = np.array(points, dtype=float)
        if self.flip_in and p.ndim in (1, 2) and p.shape[-1] == 2:  # else the model refuses
            p[..., 1] = -p[..., 1]
        out = np.array(self.model.apply(p), dtype=float)
        if self.flip_out and out.size:
            out[..., 1] = -out[..., 1]
        return out

    __call__ = apply

    def inverse(self) -> HandedTransform:
        """The inverse, target as given -> source as given (the flips change sides)."""
        return HandedTransform(self.model.inverse(), self.flip_out, self.flip_in)


def _flip_comment(t) -> str:
    """What the output comment says about row/y flips applied by ``t``."""
    if not isinstance(t, HandedTransform):
        return ""
    sides = [s for s, f in (("input", t.flip_in), ("output", t.flip_out)) if f]
    return f"; {' and '.join(sides)} row/y negated as in the estimate (extras.handedness)"


def _output_unit(given: str | None, recorded: str | None, params: Path, inverse: bool):
    """The unit of the output coordinates of ``transform apply``: ``--unit``, else the one the
    parameter file records for that side (None when neither says)."""
    if given is None:
        return recorded
    text = given.strip()
    if not text or any(c in text for c in "\r\n"):
        raise InputError(f"--unit {given!r}: give a unit name on one line, e.g. m, mm or px")
    if recorded is not None and text != recorded:
        side = "source unit (--inverse transforms to it)" if inverse else "target unit"
        raise InputError(
            f"--unit {text}: {params} records the {side} {recorded}, the unit of the "
            "transformed points; --unit names the unit of the output coordinates, it does "
            "not convert them: leave --unit out"
        )
    return text


def _output_columns(columns: tuple[str, ...]) -> list[str]:
    swapped = []
    for c in columns:
        swapped.append(c.upper() if c.islower() else c.lower() if c.isupper() else c)
    return swapped if swapped != list(columns) else [f"{c}_t" for c in columns]


@app.command("apply")
def apply(
    params: Annotated[
        Path,
        typer.Argument(
            help="Parameter JSON written by 'transform estimate --output-params' or 'orient "
            "absolute --output-params'."
        ),
    ],
    points: Annotated[Path, typer.Argument(help="CSV of points to transform.")],
    output: Annotated[
        Path | None,
        typer.Option(
            "--output",
            "-o",
            help="Output CSV (default, or -: print to stdout).",
            callback=dash_is_stdout,
        ),
    ] = None,
    inverse: Annotated[
        bool, typer.Option("--inverse", help="Apply the inverse transformation (target -> source).")
    ] = False,
    cols: Annotated[
        str | None,
        typer.Option(
            help="Coordinate columns of POINTS (default: the columns the estimate read on "
            "this side, its target columns with --inverse, when POINTS has them; else found "
            "by name)."
        ),
    ] = None,
    out_cols: Annotated[
        str | None,
        typer.Option(
            help="Names of the output coordinate columns (default: the target columns of the "
            "estimate, its source columns with --inverse; for a file that records none, x <-> X "
            "swapped)."
        ),
    ] = None,
    id_col: IdColOpt = None,
    crs: Annotated[
        str | None,
        typer.Option(
            "--crs",
            help="CRS to record in the output ('# crs:' line; default: the target CRS of the "
            "parameter file, its source CRS with --inverse); refused when it contradicts that "
            "record (it names the CRS, it does not convert).",
            show_default=False,
        ),
    ] = None,
    unit: Annotated[
        str | None,
        typer.Option(
            "--unit",
            help="Length unit of the output coordinates, recorded in a '# unit:' line "
            "(default: the target unit the parameter file records, --unit of transform "
            "estimate or orient absolute; its source unit with --inverse); refused when it "
            "contradicts that record (it names the unit, it does not convert).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Transform the points of a CSV with saved parameters (or their inverse).

    The output CSV has the id, the transformed coordinates and the role column if the input
    has one; numbers are written losslessly. The CRS of the output is recorded in a
    '# crs: ...' line; a '# crs:' line of POINTS must name the input side of the parameters.
    """
    # the parameters are no destination (-o POINTS is: the points are read before it)
    check_outputs({"PARAMS": params}, output=output)
    single_threaded_blas()
    from ..io import PointBlocks

    transform, to_crs, from_crs, (from_cols, to_cols), (from_unit, to_unit) = (
        load_transform_record(params)
    )
    if inverse:
        to_crs, from_crs = from_crs, to_crs
        to_cols, from_cols = from_cols, to_cols
        to_unit, from_unit = from_unit, to_unit
    out_unit = _output_unit(unit, to_unit, params, inverse)
    out_info = cartesian_crs_option(crs or to_crs, "--crs" if crs else f"{params}: crs")
    if crs is not None and to_crs is not None and not same_crs(to_crs, out_info.text):
        side = "source CRS (--inverse transforms to it)" if inverse else "target CRS"
        raise InputError(
            f"--crs {crs}: {params} records the {side} {to_crs}, the CRS of the transformed "
            "points; --crs names the CRS of the output coordinates, it does not convert them: "
            "leave --crs out, or convert the output with photogeom crs convert"
        )
    with column_options("--cols"):
        # without --cols: the columns the estimate read on this side (x2,y2; X,Y with
        # --inverse) when POINTS has them, before the usual names (a file with x,y and X,Y)
        blocks = PointBlocks(points, split_names(cols), id_column=id_col, prefer_columns=from_cols)
    in_crs = crs_from_comments(blocks.comments)
    if in_crs is not None:
        cartesian_crs_option(in_crs, f"{points} ('# crs:' line)")
    if in_crs is not None and from_crs is not None and not same_crs(in_crs, from_crs):
        raise InputError(
            f"{points} records the CRS {in_crs} but the parameters of {params} transform from "
            f"{from_crs}{' (--inverse)' if inverse else ''}: convert the points first "
            "(photogeom crs convert) or use the parameters of their CRS"
        )
    dim = getattr(transform, "dim", blocks.dim)
    if blocks.dim != dim:
        raise InputError(
            f"{points}: {blocks.dim} coordinate column(s) ({', '.join(blocks.columns)}) but the "
            f"{getattr(transform, 'name', 'transformation')} works on {dim}D points; choose the "
            "columns with --cols"
        )
    t = transform.inverse() if inverse else transform
    n_out = t.apply(np.zeros((1, blocks.dim))).shape[1]
    names = split_names(out_cols)
    if names is None:  # the column names of the estimate's output side, else x <-> X
        recorded = to_cols is not None and len(to_cols) == n_out
        names = list(to_cols) if recorded else _output_columns(blocks.columns)
    check_out_cols(names, n_out, role=blocks.has_roles)
    direction = "inverse of" if inverse else "forward"
    comments = [
        f"{direction} {getattr(transform, 'name', 'transformation')} from {params}; "
        f"input {points} ({', '.join(blocks.columns)})"
        + _flip_comment(t)
    ]
    if out_info is not None:
        comments.append(f"crs: {out_info.text}")
    if out_unit is not None:
        comments.append(f"unit: {out_unit}")

    def compute(block):
        return t.apply(block.coords), {}

    n = run_point_job(
        blocks, output, names, compute, comments=comments, description="transform apply",
        keep_roles=True,
    )  # fmt: skip
    if output is not None:
        say(f"wrote {n} point(s) to {output}", stderr=True)
