"""`photogeom orient absolute`: the 3D similarity (absolute orientation) from point pairs.

One CSV with both coordinate sets (``x,y,z`` and ``X,Y,Z``) or two CSVs joined by point id.
``--method`` picks one of the six methods; ``--compare`` runs them all and prints the
evaluation table (parameters, differences to the converged Gauss-Markov solution,
orthogonality defect, time per solve); ``--ransac`` rejects wrong correspondences.
"""

from __future__ import annotations

import json
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from .._lazy import LazyModule
from ..errors import InputError
from ._common import (
    CRS_FORMS,
    AlphaOpt,
    AngleUnit,
    batch_failed,
    check_alpha,
    check_mask,
    check_outputs,
    console,
    file_crs,
    json_text,
    load_pairs,
    options_in_errors,
    say,
    with_alpha,
    write_outputs,
)
from ._stream import busy

np = LazyModule("numpy")  # imported when a command needs it: quick start-up

#: The methods of :data:`photogeom.orientation.METHODS` (named here so that the command line
#: starts without importing the estimators; a test keeps the two equal).
METHODS = ("closed-form", "svd", "quaternion", "dual-quaternion", "gauss-markov", "gauss-helmert")
Method = Enum("Method", {m: m for m in METHODS}, type=str)


class Convention(str, Enum):
    """Convention of the angles of R."""

    transposed = "transposed"
    direct = "direct"


def _display_angles(fit, convention: str, unit: str) -> tuple[float, float, float]:
    """omega, phi, kappa as printed (one rule for every printed angle, see
    :func:`photogeom.units.display_angle`)."""
    from ..units import display_angle

    w, p, k = fit.angles(convention, unit)
    return (
        display_angle(w, unit, "omega"),
        display_angle(p, unit, "phi"),
        display_angle(k, unit, "kappa"),
    )


def _angle_std(fit, convention: str, unit: str) -> tuple[float, float, float] | None:
    """A-posteriori standard deviations of omega, phi, kappa in ``convention`` and ``unit``;
    None where the fit has none (no statistics, or the raw closed-form matrix, which is not a
    rotation, in the direct convention).

    The fit's parameters are the angles of the transposed convention ``R = M(a).T``; the
    direct angles ``b`` (``R = M(b)``) are those of ``R.T`` in the transposed convention, so
    their covariance is ``J C J.T`` with ``J`` the exact Jacobian of that conversion
    (:func:`~photogeom.orientation.absolute_stats.transpose_angles`): at large rotations the
    two sets of standard deviations differ (they are not a relabelling).
    """
    from ..orientation.absolute_stats import transpose_angles
    from ..units import from_radians

    names = list(fit.parameter_names)
    if not all(a in names for a in ("omega", "phi", "kappa")):
        return None
    idx = [names.index(a) for a in ("omega", "phi", "kappa")]
    C = np.asarray(fit.covariance, dtype=float)
    if C.ndim != 2 or not np.all(np.isfinite(C[np.ix_(idx, idx)])):
        return None
    C = C[np.ix_(idx, idx)]
    if convention == "direct":
        if not fit.model.check:  # raw closed form: the direct reading is another function
            return None
        _, J = transpose_angles(*(float(fit.parameters[i]) for i in idx))
        C = J @ C @ J.T
    std = np.sqrt(np.clip(np.diag(C), 0.0, None))
    return tuple(float(from_radians(v, unit)) for v in std)


def _angles_line(fit, convention: str, unit: str) -> str:
    w, p, k = _display_angles(fit, convention, unit)
    rel = "R = M(omega, phi, kappa).T" if convention == "transposed" else "R = M(omega, phi, kappa)"
    line = (
        f"angles ({convention} convention, {rel}): omega {w:.6f} {unit}, phi {p:.6f} {unit}, "
        f"kappa {k:.6f} {unit}; orthogonality defect |R.T R - I| {fit.orthogonality_defect:.2e}"
    )
    std = _angle_std(fit, convention, unit)
    if std is None:
        return line
    return (
        f"{line}\nstd. dev. of these angles (a posteriori): omega {std[0]:.3g} {unit}, "
        f"phi {std[1]:.3g} {unit}, kappa {std[2]:.3g} {unit}"
    )


def _fit_json(fit, convention: str, unit: str, pairs_notes) -> dict:
    d = fit.to_dict()
    w, p, k = _display_angles(fit, convention, unit)
    d["angles"] = {"convention": convention, "unit": unit, "omega": w, "phi": p, "kappa": k}
    std = _angle_std(fit, convention, unit)
    if std is not None:  # a-posteriori standard deviations in this convention and unit
        d["angles"]["std"] = dict(zip(("omega", "phi", "kappa"), std))
    d["scale"] = fit.scale
    d["rotation"] = np.asarray(fit.rotation).tolist()
    d["translation"] = np.asarray(fit.translation).tolist()
    d["orthogonality_defect"] = fit.orthogonality_defect
    if fit.inliers is not None:
        d["inliers"] = [bool(v) for v in fit.inliers]
    if pairs_notes:
        d["input_notes"] = list(pairs_notes)
    return d


def register(app: typer.Typer) -> None:
    """Add ``absolute`` to the ``orient`` group."""

    @app.command("absolute")
    @options_in_errors(sigma_target="--sigma-target", sigma_source="--sigma-source")
    def absolute(
        source: Annotated[
            Path,
            typer.Argument(
                help="CSV with the source (model) points, and the target points if TARGET is "
                "not given (columns x,y,z and X,Y,Z)."
            ),
        ],
        target: Annotated[
            Path | None,
            typer.Argument(help="CSV with the target (ground) points, joined by point id."),
        ] = None,
        method: Annotated[
            Method, typer.Option("--method", "-m", help="Estimation method.", case_sensitive=False)
        ] = Method.svd,
        compare: Annotated[
            bool, typer.Option("--compare", help="Run every method and print the comparison.")
        ] = False,
        as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of tables.")] = (
            False
        ),
        report: Annotated[
            Path | None, typer.Option("--report", help="Write an HTML report to this file.")
        ] = None,
        output_params: Annotated[
            Path | None,
            typer.Option(
                "--output-params",
                help="Write the estimated parameters (the --json results, JSON) to this file, "
                "for 'transform apply' and 'cloud transform --params'.",
            ),
        ] = None,
        angle_unit: Annotated[
            AngleUnit, typer.Option("--angle-unit", help="Unit of the angles shown.")
        ] = AngleUnit.deg,
        convention: Annotated[
            Convention,
            typer.Option(
                "--convention",
                help="transposed: R = M(omega, phi, kappa).T (Wolf, Kraus; the parameters); "
                "direct: R = M(omega, phi, kappa).",
            ),
        ] = Convention.transposed,
        ransac: Annotated[
            bool, typer.Option("--ransac", help="Reject wrong correspondences by RANSAC.")
        ] = False,
        threshold: Annotated[
            float | None,
            typer.Option("--threshold", help="RANSAC inlier distance (target units)."),
        ] = None,
        rigid: Annotated[
            bool, typer.Option("--rigid", help="Rigid transformation: scale fixed to 1.")
        ] = False,
        sigma_source: Annotated[
            float | None,
            typer.Option(
                help="Std. dev. of the source coordinates, in source units (--method "
                "gauss-helmert)."
            ),
        ] = None,
        sigma_target: Annotated[
            float | None,
            typer.Option(help="Std. dev. of the target coordinates, in target units (--unit)."),
        ] = None,
        initial: Annotated[
            str | None,
            typer.Option(
                help="Start of gauss-markov / gauss-helmert: a direct method or 'zeros'."
            ),
        ] = None,
        source_cols: Annotated[
            str | None, typer.Option(help="Source coordinate columns (default x,y,z).")
        ] = None,
        target_cols: Annotated[
            str | None, typer.Option(help="Target coordinate columns (default X,Y,Z).")
        ] = None,
        id_col: Annotated[
            str | None, typer.Option(help="Id column (default: id, point, point_id or name).")
        ] = None,
        check_ids: Annotated[
            str | None,
            typer.Option(
                help="Comma-separated ids of check points (default: role column 'check')."
            ),
        ] = None,
        weights_col: Annotated[
            str | None,
            typer.Option(help="Column of per-point weights (unitless; with two files: in TARGET)."),
        ] = None,
        sigma_col: Annotated[
            str | None, typer.Option(help="Column of per-point std. devs. (target units).")
        ] = None,
        unit: Annotated[
            str | None,
            typer.Option(
                help="Length unit of the target coordinates, labelling shifts, residuals and "
                "RMS (e.g. mm, m, ft) [default: the --target-crs unit, else m].",
                show_default=False,
            ),
        ] = None,
        allow_unmatched: Annotated[
            bool, typer.Option(help="Leave out ids found in only one file (listed).")
        ] = False,
        seed: Annotated[
            int | None, typer.Option(min=0, help="Random seed of RANSAC, an integer >= 0.")
        ] = None,
        alpha: AlphaOpt = None,
        source_crs: Annotated[
            str | None,
            typer.Option(
                help=f"CRS of the source points, recorded in the results ({CRS_FORMS}; "
                "default with two files: SOURCE's '# crs:' line); geographic CRSs (degrees) "
                "are refused.",
                show_default=False,
            ),
        ] = None,
        target_crs: Annotated[
            str | None,
            typer.Option(
                help="CRS of the target points (residuals, parameters), recorded in the "
                "results and the report (default: TARGET's '# crs:' line).",
                show_default=False,
            ),
        ] = None,
    ) -> None:
        """Absolute orientation: X = s R x + t from corresponding 3D points."""
        from ..report import print_fit, print_table

        check_outputs(
            {"SOURCE": source, "TARGET": target}, report=report, output_params=output_params
        )
        _check_option_combinations(
            ransac=ransac, compare=compare, threshold=threshold, seed=seed,
            sigma_source=sigma_source, initial=initial, output_params=output_params,
            method=method.value,
        )
        alpha = check_alpha(
            alpha,
            off=None if not compare else "--compare does not run (it compares the methods' "
            "parameters; no residual is tested): leave --alpha out, or drop --compare and "
            "choose the method with --method",
        )

        tcrs = file_crs(target_crs, "--target-crs", target, unit=unit)
        scrs = file_crs(source_crs, "--source-crs", source if target is not None else None)
        if unit is None:
            unit = tcrs.unit if tcrs is not None and tcrs.unit else "m"
        out = console()
        with busy(f"reading {source.name}", source, target):
            pairs = load_pairs(
                source, target, source_cols=source_cols, target_cols=target_cols, id_col=id_col,
                weights_col=weights_col, sigma_col=sigma_col, allow_unmatched=allow_unmatched,
            )
        if pairs.source.shape[1] != 3 or pairs.target.shape[1] != 3:
            raise InputError(
                "absolute orientation needs 3D points in both systems "
                f"(got {pairs.source.shape[1]}D source, {pairs.target.shape[1]}D target)"
            )
        is_check = check_mask(pairs.ids, pairs.check_mask, check_ids, list_ids=True)
        crs_record = _crs_record(tcrs, scrs, pairs)
        ctrl = ~is_check
        ids = np.asarray(pairs.ids, dtype=object)
        x, X = pairs.source[ctrl], pairs.target[ctrl]
        w = None if pairs.weights is None else pairs.weights[ctrl]
        angle = angle_unit.value
        conv = convention.value
        meth = method.value
        options: dict = {"with_scale": not rigid, "unit": unit}
        if w is not None:
            options["weights"] = w
        if sigma_target is not None:
            if w is not None:
                raise InputError("give per-point weights/sigmas or --sigma-target, not both")
            options["sigma_target"] = sigma_target
        if compare:
            from ..orientation import compare_absolute_methods

            cmp = compare_absolute_methods(
                x, X, convention=conv, angle_unit=angle, length_unit=unit,
                **{k: v for k, v in options.items() if k != "unit"},
            )
            if as_json:
                d = cmp.to_dict()
                if tcrs is not None or scrs is not None:
                    d["crs"] = crs_record["crs"]
                    d["source_crs"] = crs_record["source_crs"]
                typer.echo(json.dumps(d, indent=2))
            else:
                out.print(f"[bold]{len(x)} point pairs[/bold] ({source.name}"
                          + (f", {target.name}" if target else "") + ")")
                from rich.markup import escape

                cols = [escape(c) for c in cmp.columns()]
                rows = cmp.display_rows()  # the digits of the report's tables
                print_table(
                    "Absolute orientation: parameters of every method",
                    cols[:8],
                    [r[:8] for r in rows],
                    console=out,
                )
                print_table(
                    f"Differences to the converged {cmp.reference} solution, speed",
                    [cols[0], *cols[8:]],
                    [[r[0], *r[8:]] for r in rows],
                    console=out,
                )
                for r in cmp.rows:
                    if r.error:
                        out.print(f"{r.method}: failed: {r.error}")
                out.print(
                    f"differences are to the converged {cmp.reference} solution; times are "
                    "medians of repeated solves (parameters only)"
                )
                for line in _crs_lines(crs_record):
                    out.print(line, markup=False, highlight=False)
            if report is not None:
                from ..examples.absolute import add_comparison
                from ..report import Report  # matplotlib: only for --report

                rep = Report("Absolute orientation: method comparison")
                add_comparison(rep, cmp, title=f"{source.name}: all methods")
                if crs_record["lines"]:
                    rep.add_text("Coordinate reference systems", "\n".join(_crs_lines(crs_record)))
                rep.write(report)
                if not as_json:
                    say(f"wrote {report}", out)
            failed = [r.method for r in cmp.rows if r.error]
            if failed:  # every method ran: a batch with failed items (docs/cli.md)
                where = "in the JSON" if as_json else "above"
                others = len(cmp.rows) - len(failed)
                batch_failed(
                    f"{len(failed)} of {len(cmp.rows)} methods failed: {', '.join(failed)} "
                    f"(their errors are {where}"
                    + (f"; the other {others} are compared" if others else "")
                    + (", see the report)" if report is not None else ")")
                )
            return
        if sigma_source is not None:
            options["sigma_source"] = sigma_source
        if initial is not None:
            options["initial"] = initial
            if meth == "gauss-helmert":  # a start is used by the iterative adjustment only
                options["iterate"] = True
        row_ids = tuple(str(i) for i in ids[ctrl])
        if ransac:
            if threshold is None:
                raise InputError("--ransac needs --threshold (inlier distance, target units)")
            from ..orientation import ransac_absolute_orientation

            fit = ransac_absolute_orientation(
                x, X, threshold, method=meth, rng=seed, ids=row_ids,
                **{k: v for k, v in options.items() if k not in ("initial", "sigma_source")},
            )
        else:
            from ..orientation import absolute_orientation

            with busy(f"{meth}: {len(x)} point pairs", source, target):
                fit = absolute_orientation(x, X, meth, ids=row_ids, **options)
        fit = with_alpha(fit, alpha)  # the level of the residual table, JSON and report
        if is_check.any():
            chk = fit.transform.apply(pairs.source[is_check]) - pairs.target[is_check]
            fit = fit.with_checks(chk, [str(i) for i in ids[is_check]])
        if tcrs is not None or scrs is not None:
            from dataclasses import replace

            fit = replace(
                fit,
                crs=crs_record["crs"],
                source_crs=crs_record["source_crs"],
                notes=tuple(fit.notes) + tuple(crs_record["notes"]),
            )
        outliers = _outliers(fit, x, X, row_ids)
        data = _fit_json(fit, conv, angle, pairs.notes)
        if fit.inliers is not None:
            data["ransac"] = {
                "threshold": threshold,
                "unit": unit,
                "pair_ids": list(row_ids),
                "inlier_ids": [i for i, k in zip(row_ids, fit.inliers) if k],
                "outliers": outliers,
                "note": "inliers is a mask over pair_ids; ids and residuals are those of "
                "the inliers; outlier residuals v = computed - observed with the inlier fit",
            }
        # the columns the estimate read, so that 'transform apply' names its output columns
        data["input"] = _input_record(source, target, pairs, is_check)
        data["input"]["unit"] = unit  # of the target: the '# unit:' line of transform apply

        # Build every output in memory first; the files are then replaced as one.
        outputs: list[tuple[Path, str]] = []
        if output_params is not None:
            outputs.append((output_params, json_text(data)))
        if report is not None:
            outputs.append((report, _report_html(
                fit, meth, conv, angle, unit, X, pairs, is_check, outliers, row_ids, threshold,
            )))  # fmt: skip
        write_outputs(outputs)
        if as_json:
            typer.echo(json_text(data), nl=False)
            return
        for note in pairs.notes:
            out.print(f"note: {note}")
        print_fit(fit, console=out, angle_unit=angle, title=f"Absolute orientation ({meth})")
        out.print(_angles_line(fit, conv, angle))
        if fit.inliers is not None:
            out.print(f"RANSAC inliers: {int(fit.inliers.sum())} of {len(fit.inliers)}")
            if outliers:
                print_table(
                    f"RANSAC outliers ({len(outliers)}, not in the estimate)",
                    ["id", "v_X", "v_Y", "v_Z", "|v|"],
                    _outlier_rows(outliers),
                    console=out,
                )
                out.print(f"v = computed - observed with the inlier fit [{unit}]", markup=False)
        for path, _ in outputs:
            say(f"wrote {path}", out)


def _input_record(source: Path, target: Path | None, pairs, is_check) -> dict:
    """The ``input`` section of the JSON results: files, the coordinate columns read (``transform
    apply`` names its output columns after them), control and check counts, unmatched ids."""
    return {
        "files": [str(source)] + ([str(target)] if target is not None else []),
        "source_columns": list(pairs.source_columns),
        "target_columns": list(pairs.target_columns),
        "n_control": int((~is_check).sum()),
        "n_check": int(is_check.sum()),
        "unmatched_source": list(pairs.unmatched_source),
        "unmatched_target": list(pairs.unmatched_target),
    }


def _report_html(
    fit, meth, conv, angle, unit, X, pairs, is_check, outliers, row_ids, threshold
) -> str:
    """The HTML report of one estimate (residual plot on X, Y; RANSAC outliers)."""
    from ..report import Report

    rep = Report("Absolute orientation")
    used = X if fit.inliers is None else X[fit.inliers]
    rep.add_fit(
        fit,
        title=f"Absolute orientation ({meth})",
        angle_unit=angle,
        points=used[:, :2],
        check_points=pairs.target[is_check][:, :2] if is_check.any() else None,
        point_labels=("X", "Y"),
        point_unit=unit,
    )
    rep.add_text("Angles", _angles_line(fit, conv, angle))
    if outliers:
        rep.add_table(
            f"RANSAC outliers ({len(outliers)} of {len(row_ids)} pairs)",
            ["id", f"v_X [{unit}]", f"v_Y [{unit}]", f"v_Z [{unit}]", f"|v| [{unit}]"],
            _outlier_rows(outliers),
            note=f"Pairs farther than the threshold {threshold:g} {unit} from the "
            "RANSAC fit, left out of the estimate; v = computed - observed with the "
            "inlier fit.",
        )
    return rep.to_html()

def _check_option_combinations(
    *,
    ransac: bool,
    compare: bool,
    threshold: float | None,
    seed: int | None,
    sigma_source: float | None,
    initial: str | None,
    output_params: Path | None = None,
    method: str = "svd",
) -> None:
    """Refuse options that the chosen mode would ignore (before any file is read).

    Raises
    ------
    InputError
        ``--threshold`` or ``--seed`` without ``--ransac``; ``--compare`` with ``--ransac``;
        ``--sigma-source`` or ``--initial`` with ``--ransac`` or ``--compare`` (neither uses
        them); ``--output-params`` with ``--compare`` (no single estimate to write);
        ``--sigma-source`` with a ``--method`` other than gauss-helmert (the only one with
        errors in the source); ``--initial`` with a direct ``--method`` (which needs no start)
        or a value other than a direct method or ``zeros``.
    """
    if compare and ransac:
        raise InputError("--compare and --ransac cannot be combined")
    if compare and output_params is not None:
        raise InputError(
            "--output-params writes the parameters of one estimate, but --compare runs every "
            "method: leave out --compare and choose the method with --method"
        )
    for given, name, what in (
        (threshold is not None, "--threshold", "the RANSAC inlier distance"),
        (seed is not None, "--seed", "the random seed of RANSAC"),
    ):
        if given and not ransac:
            raise InputError(
                f"{name} applies only with --ransac ({what}); add --ransac or leave {name} out"
            )
    mode = "--ransac" if ransac else "--compare" if compare else None
    for given, name in ((sigma_source is not None, "--sigma-source"),
                        (initial is not None, "--initial")):
        if given and mode is not None:
            raise InputError(
                f"{name} is not used with {mode} (it sets up a single gauss-markov / "
                f"gauss-helmert estimate); leave it out or drop {mode}"
            )
    if mode is None:
        _check_single_estimate(method, sigma_source, initial)


#: What ``--initial`` takes: the direct methods and ``zeros`` (s = 1, R = I, t = 0).
INITIAL_VALUES = ("closed-form", "svd", "quaternion", "dual-quaternion", "zeros")


def _check_single_estimate(method: str, sigma_source: float | None, initial: str | None) -> None:
    """Refuse ``--sigma-source`` and ``--initial`` where ``--method`` does not use them, and an
    ``--initial`` that is not one of :data:`INITIAL_VALUES` (messages in the words of the
    command line; the library names its keywords)."""
    if sigma_source is not None and method != "gauss-helmert":
        raise InputError(
            f"--sigma-source gives the source coordinates errors, which --method {method} "
            "does not model (it treats them as error-free): add --method gauss-helmert, or "
            "leave --sigma-source out"
        )
    if initial is None:
        return
    if method not in ("gauss-markov", "gauss-helmert"):
        raise InputError(
            f"--initial is the start of an iterative estimate; --method {method} is direct and "
            "needs none: leave --initial out, or choose --method gauss-markov or gauss-helmert"
        )
    if initial.strip().lower() not in INITIAL_VALUES:
        raise InputError(
            f"--initial {initial}: give a direct method ({', '.join(INITIAL_VALUES[:-1])}) or "
            "zeros (scale 1, no rotation, no shift)"
        )


def _crs_record(tcrs, scrs, pairs) -> dict:
    """The CRS texts, their readable lines and the curvature notes of the point sets."""
    from ..crs import curvature_note

    rec: dict = {"crs": None, "source_crs": None, "lines": [], "notes": []}
    for info, pts, side, key in (
        (scrs, pairs.source, "source", "source_crs"),
        (tcrs, pairs.target, "target", "crs"),
    ):
        if info is None:
            continue
        rec[key] = info.text
        rec["lines"].append(f"{side} CRS: {info.name}")
        note = curvature_note(info, pts, what=f"{side} coordinates")
        if note:
            rec["notes"].append(note)
    return rec


def _crs_lines(rec: dict) -> list[str]:
    return list(rec["lines"]) + [f"note: {n}" for n in rec["notes"]]


def _outliers(fit, x, X, row_ids) -> list[dict]:
    """Pairs rejected by RANSAC: id, residual v = computed - observed (inlier fit), |v|."""
    if fit.inliers is None:
        return []
    k = np.flatnonzero(~np.asarray(fit.inliers))
    v = fit.transform.apply(x[k]) - X[k]
    norms = np.linalg.norm(v, axis=1)
    return [
        {"id": row_ids[i], "v": [float(c) for c in vi], "norm": float(n)}
        for i, vi, n in zip(k, v, norms)
    ]


def _outlier_rows(outliers: list[dict]) -> list[list[str]]:
    return [[o["id"], *(f"{c:.4f}" for c in o["v"]), f"{o['norm']:.4f}"] for o in outliers]
