"""Worked examples of 2D transformations on the bundled lecture data.

* ``fiducials`` - interior orientation of an analog photo: 2D similarity from four fiducial
  marks (control), checked on four others (lecture example 4);
* ``two-images`` - six tie points on two digital images: 2D similarity, affine and
  projective (lecture example 5).

Each example prints the fit and compares it with the published numbers, digit by digit.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence

import numpy as np

from .. import datasets
from ..estimation import estimate_transform
from ..io import read_point_pairs
from ..report.console import fit_text
from ..report.format import as_text_table
from . import Example

# Published values (analytical photogrammetry lecture; see the transformations spec).
EX4_PARAMETERS = {"a": "1.0000354", "b": "-0.0000022", "c": "130.00875", "d": "130.009"}
EX4_CONTROL = {
    "1": ("-0.00225", "0.00425"),
    "2": ("-0.00025", "-0.00225"),
    "3": ("0.0045", "0.0"),
    "4": ("-0.002", "-0.002"),
}
EX4_CHECK = {
    "5": ("0.0045", "0.00725"),
    "6": ("-0.001", "0.00075"),
    "7": ("-0.0085", "0.00575"),
    "8": ("-0.001", "0.00225"),
}
EX5_PARAMETERS = {
    "similarity2d": ("1.86", "0.48", "-62.16", "89.33"),
    "affine2d": ("2.62", "1.72", "-298.19", "0.31", "2.88", "-127.03"),
    "projective2d": ("0.975", "-0.029", "5.445", "-0.015", "0.97", "3.91", "-0.001", "-0.003"),
}
#: The lecture's "RMSE" of example 5: sqrt(v'v / 8) of the linear least-squares solutions.
EX5_RMSE = {"similarity2d": "41.2096", "affine2d": "18.6572", "projective2d": "0.21"}


def _decimals(published: str) -> int:
    return len(published.split(".")[1]) if "." in published else 0


def agrees(value: float, published: str) -> bool:
    """True when ``value`` rounds to the published number at its printed digits (a value
    exactly half-way, e.g. -62.165 printed as -62.16, counts as agreeing)."""
    half = 0.5 * 10.0 ** -_decimals(published)
    return abs(float(value) - float(published)) <= half * (1 + 1e-6)


def agreement(value: float, published: str) -> str:
    """``"yes"``; ``"yes, rounded via R"`` when the published figure results from rounding
    twice (first to one more digit, R); else ``"NO"``."""
    if agrees(value, published):
        return "yes"
    via = round(float(value), _decimals(published) + 1)
    if agrees(via, published):
        return f"yes, rounded via {via:g}"
    return "NO"


def _comparison(rows: Sequence[tuple[str, float, str]]) -> tuple[list, list]:
    """Rows ``quantity, photogeom (3 more decimals than published), published, verdict``."""
    cols = ["quantity", "photogeom", "published", "agrees to the printed digits"]
    out = []
    for name, value, pub in rows:
        out.append([name, f"{value:.{_decimals(pub) + 3}f}", pub, agreement(value, pub)])
    return cols, out


def _fit_block(fit, title: str) -> str:
    return fit_text(fit, title=title, width=100).rstrip()


# --- example 4 --------------------------------------------------------------------------------


def run_fiducials(report=None) -> str:
    """Lecture example 4: interior orientation by a 2D similarity, control and check marks."""
    pairs = read_point_pairs(datasets.path("lecture_fiducials"))
    fit = estimate_transform(
        "similarity2d",
        pairs.source,
        pairs.target,
        check=pairs.check_mask,
        ids=pairs.ids,
        unit="mm",
    )
    intro = (
        "Eight fiducial marks of an analog aerial photo: calibrated coordinates (x, y) from the "
        "camera certificate and comparator coordinates (X, Y) measured on the photo, mm. "
        "Marks 1-4 determine the 2D similarity X = a x + b y + c, Y = -b x + a y + d "
        "(calibrated -> machine); marks 5-8 are check points and do not enter the estimate."
    )
    rows = [(k, fit.params[k], v) for k, v in EX4_PARAMETERS.items()]
    ids = list(fit.ids)
    for pid, (vx, vy) in EX4_CONTROL.items():
        r = fit.residuals[ids.index(pid)]
        rows += [(f"v_x control {pid} [mm]", r[0], vx), (f"v_y control {pid} [mm]", r[1], vy)]
    cids = list(fit.check_ids)
    for pid, (vx, vy) in EX4_CHECK.items():
        r = fit.check_residuals[cids.index(pid)]
        rows += [(f"v_x check {pid} [mm]", r[0], vx), (f"v_y check {pid} [mm]", r[1], vy)]
    cols, table = _comparison(rows)
    n_ok = sum(r[3].startswith("yes") for r in table)
    verdict = f"{n_ok} of {len(table)} published numbers reproduced to the printed digits."
    text = "\n\n".join(
        [
            textwrap.fill(intro, 100),
            _fit_block(fit, "2D similarity, calibrated -> machine (marks 1-4 control, 5-8 check)"),
            "Comparison with the lecture (residuals v = computed - observed, mm):",
            as_text_table(cols, table),
            verdict,
        ]
    )
    if report is not None:
        report.add_text("Data", intro)
        mask = pairs.check_mask
        report.add_fit(
            fit,
            title="2D similarity, calibrated -> machine coordinates",
            points=pairs.target[~mask],
            check_points=pairs.target[mask],
            point_labels=("X", "Y"),
            point_unit="mm",
        )
        report.add_table("Comparison with the published numbers", cols, table, note=verdict)
    return text


# --- example 5 --------------------------------------------------------------------------------


def run_two_images(report=None) -> str:
    """Lecture example 5: image 2 -> image 1 by a similarity, an affine and a projective."""
    pairs = read_point_pairs(datasets.path("lecture_two_images"), "x2,y2", "x1,y1")
    intro = (
        "Six tie points measured on two digital images (pixels). The points of image 2 "
        "(x2, y2) are transformed into image 1 (x1, y1) with three models of increasing "
        "generality. The projective model is finished by a nonlinear Gauss-Markov adjustment "
        "of the rational equations; the lecture prints the linearised solution "
        "x = a1 x' + a2 y' + a3 - c1 x' x - c2 y' x (observations on both sides), which is "
        "also shown. The lecture's 'RMSE' is sqrt(v'v / 8) for all three models: for the "
        "similarity (redundancy 8) it is sigma0, for the others it is neither sigma0 nor the "
        "per-point RMSE."
    )
    blocks = [textwrap.fill(intro, 100)]
    summary_rows = []
    compare_rows = []
    fits = {}
    for model, label in (
        ("similarity2d", "2D similarity (4 parameters)"),
        ("affine2d", "2D affine (6 parameters)"),
        ("projective2d", "2D projective (8 parameters)"),
    ):
        fit = estimate_transform(model, pairs.source, pairs.target, ids=pairs.ids, unit="px")
        fits[model] = fit
        blocks.append(_fit_block(fit, f"{label}, image 2 -> image 1"))
        if model == "projective2d":
            lin = fit.extras["linearised"]
            values = [lin["parameters"][n] for n in fit.parameter_names]
            vtv = float(lin["vtv"])
            kind = "linearised solution"
        else:
            values = list(fit.parameters)
            vtv = float(np.sum(np.asarray(fit.residuals) ** 2))
            kind = "estimate"
        for name, value, pub in zip(fit.parameter_names, values, EX5_PARAMETERS[model]):
            compare_rows.append((f"{model} {name} ({kind})", value, pub))
        lecture_rmse = float(np.sqrt(vtv / 8.0))
        compare_rows.append((f"{model} sqrt(v'v / 8) ({kind})", lecture_rmse, EX5_RMSE[model]))
        summary_rows.append(
            [
                label,
                str(fit.redundancy),
                f"{fit.sigma0:.4f}",
                f"{fit.rmse:.4f}",
                f"{lecture_rmse:.4f}",
                EX5_RMSE[model],
            ]
        )
    s_cols = [
        "model",
        "redundancy",
        "sigma0 [px]",
        "RMSE per point [px]",
        "sqrt(v'v/8) [px]",
        "lecture 'RMSE'",
    ]
    cols, table = _comparison(compare_rows)
    n_ok = sum(r[3].startswith("yes") for r in table)
    verdict = f"{n_ok} of {len(table)} published numbers reproduced to the printed digits."
    blocks += [
        "Model comparison (the projective model fits the six points to a few tenths of a pixel):",
        as_text_table(s_cols, summary_rows),
        "Comparison with the lecture:",
        as_text_table(cols, table),
        verdict,
    ]
    if report is not None:
        report.add_text("Data", intro)
        report.add_table("Model comparison", s_cols, summary_rows)
        for model, fit in fits.items():
            report.add_fit(
                fit,
                title=f"{model}: image 2 -> image 1",
                points=pairs.target,
                point_labels=("x1", "y1"),
                point_unit="px",
            )
        report.add_table("Comparison with the published numbers", cols, table, note=verdict)
    return "\n\n".join(blocks)


EXAMPLES = [
    Example(
        "fiducials",
        "Interior orientation: 2D similarity from 4 fiducial marks, 4 check marks "
        "(lecture example 4)",
        run_fiducials,
    ),
    Example(
        "two-images",
        "Two images: 2D similarity, affine and projective from 6 tie points (lecture example 5)",
        run_two_images,
    ),
]
