"""Worked examples of 2D transformations on the bundled lecture data.

* ``fiducials`` - interior orientation of an analog photo: 2D similarity from four fiducial
  marks (control), checked on four others (lecture example 4);
* ``two-images`` - six tie points on two digital images: 2D similarity, affine and
  projective (lecture example 5);
* ``lecture-models`` - the lecture's examples with given parameters: parametric forms of a
  2D similarity and affine (1, 2), the three 2D models applied to points (3), fiducial and
  pixel to image coordinates (6, 7), the rotation matrix and a 3D similarity (8), a 3D affine
  (9) and a 3D projective (10).

Each example prints the fit and compares it with the published numbers, digit by digit.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence

import numpy as np

from .. import datasets
from ..estimation import estimate_transform
from ..imagecoords import fiducial_to_image, pixel_to_image
from ..io import read_point_pairs
from ..report.console import fit_text
from ..report.format import as_text_table, fmt_fixed
from ..rotation import opk_matrix
from ..transforms import (
    Affine2D,
    Affine3D,
    Projective2D,
    Projective3D,
    Similarity2D,
    Similarity3D,
)
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
    twice (first to one more digit, R); ``"yes, truncated (not rounded)"`` when it is the
    value cut off after its printed digits; else ``"NO"``."""
    if agrees(value, published):
        return "yes"
    decimals = _decimals(published)
    via = round(float(value), decimals + 1)
    if agrees(via, published):
        return f"yes, rounded via {via:g}"
    cut = np.trunc(float(value) * 10.0**decimals) / 10.0**decimals
    if abs(cut - float(published)) <= 1e-9 * 10.0**-decimals:
        return "yes, truncated (not rounded)"
    return "NO"


def _comparison(rows: Sequence[tuple[str, float, str]]) -> tuple[list, list]:
    """Rows ``quantity, photogeom (3 more decimals than published), published, verdict``."""
    cols = ["quantity", "photogeom", "published", "agrees to the printed digits"]
    out = []
    for name, value, pub in rows:
        out.append([name, fmt_fixed(value, _decimals(pub) + 3), pub, agreement(value, pub)])
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

# --- examples 1-3 and 6-10: models with given parameters ---------------------------------------

#: The points of lecture example 3, (x', y').
EX3_POINTS = np.array([(113.02, 0.002), (-112.99, 112.99), (113.01, -113.01)])
#: Published results of lecture examples 1-3 and 6-10 (02-transformations.md).
EX1_PARAMETERS = {"a": "0.9962", "b": "-0.0872", "c": "125", "d": "130"}
EX2_PARAMETERS = {
    "a1": "0.9472",
    "a2": "-0.0738",
    "b1": "0.0898",
    "b2": "1.0260",
    "a3": "125",
    "b3": "130",
}
EX3_POINTS_OUT = {
    "similarity": (("243.1196", "152.6060"), ("-5.488", "220.3920"), ("265.712", "39.5920")),
    "affine": (("232.2388", "133.7531"), ("18.6595", "241.5420"), ("233.3595", "14.6380")),
    "projective": (("173.4458", "99.8925"), ("-4.2182", "-54.6040"), ("36.3235", "2.2785")),
}
EX6_IMAGE = ("83.094", "63.474", "-152")
EX7_IMAGE = ("-41.808", "-31.548", "-120")
EX8_MATRIX = (
    ("0.620885", "0.7832956", "-0.030816"),
    ("-0.739942", "0.5985935", "0.306874"),
    ("0.258819", "-0.1677312", "0.951251"),
)
EX8_POINT = ("270.8707", "1501.3692", "443.5540")
EX9_ROWS = [[0.6, -0.7, 0.3, -200.0], [0.8, 0.6, 0.2, 136.0], [-0.1, 0.3, 0.9, 189.0]]
EX9_POINT = ("270", "1574.4", "339.2")
EX10_HOMOGENEOUS = ("270", "1574.4", "339.2", "25.48")
EX10_POINT = ("10.5965", "61.7896", "13.3124")


def _rows(label: str, values, published) -> list[tuple[str, float, str]]:
    """Comparison rows ``(label name, value, published)`` of flat values and names."""
    flat = np.asarray(values, dtype=float).reshape(-1)
    return [(f"{label} {name}", float(v), pub) for (name, pub), v in zip(published, flat)]


def run_lecture_models(report=None) -> str:
    """Lecture examples 1-3 and 6-10: models with given parameters, against the printed
    numbers (parameters unitless, coordinates mm or the lecture's units, angles deg)."""
    sim = Similarity2D.from_textbook(1.0, 5.0, 125.0, 130.0, unit="deg")
    aff = Affine2D.from_textbook(0.95, 1.03, 5.0, 0.5, 125.0, 130.0, unit="deg")
    models3 = {
        "similarity": Similarity2D(1.0, -0.2, 130.1, 130.0),
        "affine": Affine2D(0.94, -0.01, 126.0, 0.05, 1.054, 128.1),
        "projective": Projective2D.from_parameters(
            [0.94, -0.01, 126.0, 0.05, 1.054, 128.1, 0.003, -0.045]
        ),
    }
    fid = fiducial_to_image((83.106, 63.466), (0.012, -0.008), 152.0)
    pix = pixel_to_image(
        (356.0, 9541.0), pixel_size=0.012, principal_point=(3840.0, 6912.0), focal_length=120.0
    )
    M = opk_matrix(*np.radians([10.0, 15.0, 50.0]))
    sim3 = Similarity3D.from_angles(
        1.0, 10.0, 15.0, 50.0, [-200.0, 136.0, 189.0], convention="transposed", unit="deg"
    )
    point3 = np.array([1354.0, 547.0, 135.0])
    aff3 = Affine3D.from_matrix(EX9_ROWS)
    proj3 = Projective3D(np.vstack([EX9_ROWS, [0.01, 0.02, 0.0, 1.0]]))

    rows = _rows("1: similarity", [sim.a, sim.b, sim.c, sim.d], EX1_PARAMETERS.items())
    rows += _rows(
        "2: affine",
        [getattr(aff, n) for n in EX2_PARAMETERS],
        EX2_PARAMETERS.items(),
    )
    for name, model in models3.items():
        out = model.apply(EX3_POINTS)
        for i, pub in enumerate(EX3_POINTS_OUT[name]):
            rows += _rows(f"3: {name}, point {i + 1}", out[i], zip(("x", "y"), pub))
    rows += _rows("6: fiducial -> image [mm]", fid, zip(("x", "y", "z"), EX6_IMAGE))
    rows += _rows("7: pixel -> image [mm]", pix, zip(("x", "y", "z"), EX7_IMAGE))
    names = [f"m{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]
    rows += _rows("8: M", M, zip(names, np.ravel(EX8_MATRIX)))
    rows += _rows("8: M.T x + t", sim3.apply(point3), zip(("X", "Y", "Z"), EX8_POINT))
    rows += _rows("9: affine", aff3.apply(point3), zip(("X", "Y", "Z"), EX9_POINT))
    rows += _rows(
        "10: homogeneous",
        proj3.apply_homogeneous(point3),
        zip(("X", "Y", "Z", "W"), EX10_HOMOGENEOUS),
    )
    rows += _rows("10: projective", proj3.apply(point3), zip(("X", "Y", "Z"), EX10_POINT))

    intro = (
        "The lecture's examples with given parameters: 1, the parametric form of a 2D "
        "similarity (theta = 5 deg, s = 1, shifts 125 and 130 mm); 2, of a 2D affine (sx 0.95, "
        "sy 1.03, e 0.5 deg, theta 5 deg); 3, a similarity, an affine and a projective "
        "applied to three points; 6, a fiducial point to image coordinates (principal point "
        "(0.012, -0.008) mm, f = 152 mm; the slide's 83.94 is a typo); 7, pixel (col 356, row "
        "9541) to image coordinates (principal point col 3840, row 6912, 12 um, f = 120 mm); "
        "8, M(omega, phi, kappa) of 10/15/50 deg and X = M.T x + t (the transposed "
        "convention); 9, a 3D affine; 10, a 3D projective."
    )
    cols, table = _comparison(rows)
    n_ok = sum(r[3].startswith("yes") for r in table)
    verdict = f"{n_ok} of {len(table)} published numbers reproduced to the printed digits."
    note = (
        "m32 = -0.16773126 is printed -0.1677312 (cut off after 7 decimals; every other "
        "element is rounded)."
    )
    text = "\n\n".join(
        [
            textwrap.fill(intro, 100),
            "Comparison with the lecture:",
            as_text_table(cols, table),
            verdict,
            note,
        ]
    )
    if report is not None:
        report.add_text("Lecture examples 1-3 and 6-10", intro)
        report.add_table(
            "Comparison with the published numbers", cols, table, note=f"{verdict} {note}"
        )
    return text


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
    Example(
        "lecture-models",
        "Lecture examples 1-3, 6-10: 2D and 3D models, image coordinates, rotation",
        run_lecture_models,
    ),
]
