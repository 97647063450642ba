"""Worked examples of frame camera models (04-camera-models.md).

* ``collinearity`` - an aerial photo: ground point -> image coordinates in mm;
* ``digital-camera`` - a digital camera: ground point -> pixel (col, row);
* ``affine-camera`` - the 8-parameter affine (parallel) camera;
* ``dlt`` - the DLT parameters of the aerial photo's orientation, and back;
* ``resection`` - space resection from simulated control points with image noise.

Each example compares its numbers with the published ones at their printed digits.
"""

from __future__ import annotations

import textwrap

import numpy as np

from ..camera import (
    AffineCamera,
    ExteriorOrientation,
    InteriorOrientation,
    dlt_from_orientation,
    orientation_from_dlt,
    project,
)
from ..camera.dlt import NAMES as DLT_NAMES
from ..orientation.resection import space_resection
from ..report.console import fit_text
from ..report.format import as_text_table, fmt_fixed
from . import Example

GROUND = np.array([1300.0, 650.0, 169.0])
PUBLISHED_DLT = (
    "0.0921",
    "0.0164",
    "-0.0043",
    "-109.9007",
    "-0.0162",
    "0.0921",
    "0.0041",
    "-67.9431",
    "-0.000032205",
    "0.000021446",
    "-0.00061413",
)


def _decimals(published: str) -> int:
    return len(published.split(".")[1]) if "." in published else 0


def _agrees(value: float, published: str) -> str:
    half = 0.5 * 10.0 ** -_decimals(published)
    return "yes" if abs(float(value) - float(published)) <= half * (1 + 1e-9) else "NO"


def _compare(rows) -> tuple[list[str], list[list[str]], str]:
    cols = ["quantity", "photogeom", "published", "agrees to the printed digits"]
    table = [
        [name, fmt_fixed(value, _decimals(pub) + 3), pub, _agrees(value, pub)]
        for name, value, pub in rows
    ]
    n_ok = sum(r[3] == "yes" for r in table)
    return (
        cols,
        table,
        f"{n_ok} of {len(table)} published numbers reproduced to the printed digits.",
    )


def _finish(intro: str, blocks: list[str], rows, report, title: str) -> str:
    cols, table, verdict = _compare(rows)
    if report is not None:
        report.add_text(title, intro)
        report.add_table("Comparison with the published numbers", cols, table, note=verdict)
    return "\n\n".join([textwrap.fill(intro, 100), *blocks, as_text_table(cols, table), verdict])


def aerial_camera() -> tuple[InteriorOrientation, ExteriorOrientation]:
    """The aerial photo of the collinearity and DLT examples."""
    return (
        InteriorOrientation(152.14, 0.008, -0.12, unit="mm"),
        ExteriorOrientation.from_degrees(1114.0, 862.0, 1600.0, 2.0, 3.0, 10.0),
    )


def run_collinearity(report=None) -> str:
    """Ground point -> image coordinates of an aerial photo (collinearity equations)."""
    io, eo = aerial_camera()
    x, y = project(GROUND, io, eo)
    intro = (
        "Aerial photo: principal distance f = 152.14 mm, principal point (0.008, -0.12) mm, "
        "omega/phi/kappa = 2/3/10 deg, projection centre (1114, 862, 1600) m. The ground point "
        "(1300, 650, 169) m is projected with the collinearity equations "
        "x - x0 = -f (m11 dX + m12 dY + m13 dZ) / (m31 dX + m32 dY + m33 dZ) (and y)."
    )
    return _finish(
        intro,
        [f"image coordinates: x = {x:.6f} mm, y = {y:.6f} mm"],
        [("x [mm]", x, "22.7354"), ("y [mm]", y, "-32.7917")],
        report,
        "Collinearity",
    )


def run_digital_camera(report=None) -> str:
    """Ground point -> pixel of a digital camera (pixel <-> image conventions)."""
    io = InteriorOrientation.digital(10000.0, 3840.0, 6912.0, pixel_size=0.012)
    eo = ExteriorOrientation.from_degrees(1160.0, 792.0, 1500.0, 1.5, 2.0, 4.0)
    col, row = project(GROUND, io, eo, system="pixel")
    x, y = project(GROUND, io, eo)
    intro = (
        "Digital camera: 12 um pixels, f = 10000 px (120 mm), principal point at column 3840, "
        "row 6912 (top-left pixel centre = (0, 0)); omega/phi/kappa = 1.5/2/4 deg, projection "
        "centre (1160, 792, 1500) m. Image coordinates x = col - col_pp, y = -(row - row_pp) "
        "(right-handed; the minus sign flips the downward rows)."
    )
    return _finish(
        intro,
        [f"image coordinates: x = {x:.4f} px, y = {y:.4f} px -> col = {col:.4f}, row = {row:.4f}"],
        [("col [px]", col, "5152.8"), ("row [px]", row, "8345.3")],
        report,
        "Digital camera",
    )


def run_affine_camera(report=None) -> str:
    """The 8-parameter affine (parallel projection) camera."""
    cam = AffineCamera((0.3, -0.2, 0.0004, 8060.0), (-0.29, 0.18, 0.0005, 9600.0))
    x, y = cam.project(GROUND)
    intro = (
        "Affine camera x = a1 X + a2 Y + a3 Z + a4, y = b1 X + b2 Y + b3 Z + b4 with "
        "a = (0.3, -0.2, 0.0004, 8060), b = (-0.29, 0.18, 0.0005, 9600), ground point "
        "(1300, 650, 169)."
    )
    return _finish(
        intro,
        [f"image coordinates: x = {x:.6f} px, y = {y:.6f} px"],
        [("x [px]", x, "8320.0676"), ("y [px]", y, "9340.0845")],
        report,
        "Affine camera",
    )


def run_dlt(report=None) -> str:
    """DLT parameters of the aerial photo, decomposition back, and agreement of projections."""
    io, eo = aerial_camera()
    L = dlt_from_orientation(io, eo)
    io2, eo2 = orientation_from_dlt(L, "mm")
    a = eo2.angles_in("deg")
    rng = np.random.default_rng(0)
    xn = rng.uniform(-0.7, 0.7, (1000, 2))
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(1000)]) * rng.uniform(1200, 1600, (1000, 1))
    pts = eo.position + pc @ eo.matrix
    from ..camera import DLT

    diff = np.abs(DLT(L).project(pts) - project(pts, io, eo)).max()
    intro = (
        "The orientation of the collinearity example expressed as the 11 DLT parameters "
        "(Q = -1 / (m31 X0 + m32 Y0 + m33 Z0), L1 = (x0 m31 - c m11) Q, ...), decomposed back "
        "into interior and exterior orientation, and used to project 1000 random points."
    )
    blocks = [
        "\n".join(f"{n:<4} {v: .10g}" for n, v in zip(DLT_NAMES, L)),
        f"decomposed: cx = {io2.fx:.10f}, cy = {io2.fy:.10f}, x0 = {io2.x0:.10f}, "
        f"y0 = {io2.y0:.10f} mm; X0 = ({eo2.X0:.6f}, {eo2.Y0:.6f}, {eo2.Z0:.6f}) m; "
        f"omega/phi/kappa = {a[0]:.10f}/{a[1]:.10f}/{a[2]:.10f} deg",
        f"largest difference DLT vs collinearity projection of 1000 points: {diff:.2e} mm",
    ]
    rows = [(n, v, p) for n, v, p in zip(DLT_NAMES, L, PUBLISHED_DLT)]
    return _finish(intro, blocks, rows, report, "DLT")


def run_resection(report=None) -> str:
    """Space resection from 12 simulated control points with 3 um image noise."""
    io, eo = aerial_camera()
    rng = np.random.default_rng(42)
    n = 12
    ground = np.column_stack(
        [rng.uniform(500, 1700, n), rng.uniform(300, 1400, n), rng.uniform(100, 350, n)]
    )
    sigma = 0.003
    image = project(ground, io, eo) + rng.normal(0, sigma, (n, 2))
    ids = [f"C{i + 1}" for i in range(n)]
    fit = space_resection(
        ground[:10],
        image[:10],
        io,
        sigma=sigma,
        ids=ids[:10],
        check_ground=ground[10:],
        check_image=image[10:],
        check_ids=ids[10:],
    )
    est = fit.exterior
    truth = eo.parameters
    std = np.array([fit.std_errors[k] for k in fit.parameter_names])
    z = (est.parameters - truth) / std
    intro = (
        "Space resection of the aerial photo from 10 simulated control points (image noise "
        "3 um, seed 42) and 2 check points: closed-form P3P start values, then a Gauss-Markov "
        "adjustment of the collinearity equations. The estimate is compared with the true "
        "orientation in units of its standard deviations."
    )
    lines = [fit_text(fit, title="Space resection", width=100).rstrip()]
    lines.append(
        "estimate - truth in standard deviations: "
        + ", ".join(f"{k} {v:+.2f}" for k, v in zip(fit.parameter_names, z))
    )
    if report is not None:
        report.add_text("Space resection", intro)
        report.add_fit(
            fit,
            title="Space resection (simulated control)",
            points=image[:10],
            check_points=image[10:],
            point_labels=("x", "y"),
            point_unit="mm",
        )
    return "\n\n".join([textwrap.fill(intro, 100), *lines])


EXAMPLES = [
    Example("collinearity", "Collinearity: ground point -> aerial photo (mm)", run_collinearity),
    Example(
        "digital-camera", "Digital camera: ground point -> pixel (col, row)", run_digital_camera
    ),
    Example("affine-camera", "8-parameter affine camera", run_affine_camera),
    Example("dlt", "DLT parameters from interior + exterior orientation, and back", run_dlt),
    Example("resection", "Space resection from simulated control points", run_resection),
]
