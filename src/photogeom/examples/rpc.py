"""Worked examples of rational polynomial (RPC) camera models on the bundled vendor files.

* ``rpc-files`` - read every bundled RPC file (five formats and sensors) and describe it;
* ``rpc-round-trip`` - project and localise over each image at three heights, and report how
  well ``localize(project(x)) = x`` holds;
* ``rpc-bias`` - bias compensation of a WorldView-2 RPC with four simulated control points
  (10 px shift, 1e-4 drift, 0.3 px noise): shift, shift+drift and affine corrections checked
  on 20 check points.
"""

from __future__ import annotations

import textwrap

import numpy as np

from .. import datasets
from ..report.console import fit_text
from ..report.format import as_text_table
from ..rpc import RPC, refine_rpc
from . import Example

FILES = ("quickbird", "ikonos", "skysat", "pleiades", "worldview2")


def _load() -> dict[str, RPC]:
    return {name: RPC.from_file(datasets.path(name)) for name in FILES}


def run_files(report=None) -> str:
    """Read every bundled RPC file and describe it."""
    models = _load()
    cols = ["file", "format", "image size (px)", "centre lon (deg)", "centre lat (deg)",
            "height range (m)"]  # fmt: skip
    rows = []
    for name, rpc in models.items():
        c0, c1, r0, r1 = rpc.image_bounds
        lon, lat = rpc.localize(0.5 * (c0 + c1), 0.5 * (r0 + r1), rpc.height_off)
        size = f"{rpc.image_size[0]} x {rpc.image_size[1]}" if rpc.image_size else "-"
        lo, hi = rpc.height_range
        rows.append([name, rpc.source, size, f"{float(lon):.6f}", f"{float(lat):.6f}",
                     f"{lo:g} .. {hi:g}"])  # fmt: skip
    intro = (
        "Five RPC00B models as the vendors ship them: QuickBird (KEY: value lists), IKONOS and "
        "SkySat (_RPC.TXT with numbered keys), Pleiades (DIMAP v2 XML, whose pixel origin "
        "(1, 1) is converted to the library's (0, 0) = centre of the first pixel), WorldView-2 "
        "(DigitalGlobe XML with an RPB block). Image centre localised at HEIGHT_OFF."
    )
    details = "\n\n".join(rpc.summary() for rpc in models.values())
    text = "\n\n".join([textwrap.fill(intro, 100), as_text_table(cols, rows), details])
    if report is not None:
        report.add_text("Bundled RPC files", intro)
        report.add_table("Models", cols, rows)
        report.add_text("Details", details, pre=True)
    return text


def run_round_trip(report=None) -> str:
    """Project/localise round trip over each image at three heights."""
    models = _load()
    cols = ["file", "points", "max |d lon| (deg)", "max |d lat| (deg)", "max |d col|, |d row| (px)",
            "Newton iterations (max)", "approx. inverse error (px)"]  # fmt: skip
    rows = []
    for name, rpc in models.items():
        c0, c1, r0, r1 = rpc.image_bounds
        C, R = np.meshgrid(np.linspace(c0, c1, 41), np.linspace(r0, r1, 41))
        dl = dp = dpx = 0.0
        its = 0
        for h in (rpc.height_range[0], rpc.height_off, rpc.height_range[1]):
            res = rpc.localize(C.ravel(), R.ravel(), h, full_output=True)
            its = max(its, int(res.iterations.max()))
            c, r = rpc.project(res.lon, res.lat, h)
            dpx = max(
                dpx, float(np.max(np.abs(c - C.ravel()))), float(np.max(np.abs(r - R.ravel())))
            )
            lon, lat = rpc.localize(c, r, h)
            dl = max(dl, float(np.max(np.abs(lon - res.lon))))
            dp = max(dp, float(np.max(np.abs(lat - res.lat))))
        from ..rpc.localization import approximate_inverse

        inv = approximate_inverse(rpc)
        rows.append([name, 3 * C.size, f"{dl:.1e}", f"{dp:.1e}", f"{dpx:.1e}", its,
                     f"{inv.max_error_px:.2g}"])  # fmt: skip
    intro = (
        "A 41 x 41 grid of pixels over each image at the lowest, middle and highest height of "
        "the model is localised (Newton iteration from a fitted approximate inverse), projected "
        "back, and localised again. The columns give the largest differences."
    )
    text = "\n\n".join([textwrap.fill(intro, 100), as_text_table(cols, rows)])
    if report is not None:
        report.add_text("Round trip", intro)
        report.add_table("localize(project(x)) - x", cols, rows)
    return text


def simulated_control(seed: int = 2024):
    """WorldView-2 RPC, 4 control + 20 check points, true and observed image positions."""
    rpc = RPC.from_file(datasets.path("worldview2"))
    rng = np.random.default_rng(seed)
    c0, c1, r0, r1 = rpc.image_bounds
    cc = np.array([0.1, 0.9, 0.1, 0.9]) * (c1 - c0) + c0
    rc = np.array([0.1, 0.15, 0.85, 0.9]) * (r1 - r0) + r0
    cols = np.concatenate([cc, rng.uniform(c0, c1, 20)])
    rows = np.concatenate([rc, rng.uniform(r0, r1, 20)])
    h = rng.uniform(0.0, 300.0, cols.size)
    lon, lat = rpc.localize(cols, rows, h)
    ground = np.column_stack([lon, lat, h])
    c, r = rpc.project(lon, lat, h)
    true = np.column_stack([c + 10.0 + 1e-4 * r, r - 7.0 + 1e-4 * r])
    observed = true + rng.normal(0.0, 0.3, true.shape)
    return rpc, ground, true, observed


def run_bias(report=None) -> str:
    """Bias compensation with four simulated control points."""
    rpc, ground, true, observed = simulated_control()
    ids = [f"C{i + 1}" for i in range(4)]
    check_ids = [f"K{i + 1}" for i in range(20)]
    raw = np.column_stack(rpc.project(*ground[4:].T)) - true[4:]
    intro = (
        "A WorldView-2 RPC whose true image positions are shifted by (10, -7) px and drift by "
        "1e-4 px per row (about 2 px over the image). Four control points near the corners "
        "are measured with 0.3 px noise; 20 check points (true positions) judge the result. "
        f"Before compensation the check-point RMSE is {np.sqrt(np.sum(raw**2) / 20):.2f} px."
    )
    blocks = [textwrap.fill(intro, 100)]
    cols = ["model", "parameters", "sigma0", "check RMSE (px)"]
    rows = []
    for model in ("shift", "shift+drift", "affine"):
        fit = refine_rpc(
            rpc, ground[:4], observed[:4], model=model, sigma=0.3, ids=ids,
            check_ground=ground[4:], check_image=true[4:], check_ids=check_ids,
        )  # fmt: skip
        rows.append([model, len(fit.parameter_names), f"{fit.sigma0:.3g}", f"{fit.check_rmse:.3f}"])
        blocks.append(fit_text(fit, title=f"bias compensation: {model}", width=100).rstrip())
        if report is not None:
            report.add_fit(
                fit, title=f"Bias compensation: {model}", points=observed[:4],
                check_points=true[4:], point_labels=("col", "row"), point_unit="px", y_down=True,
            )  # fmt: skip
    blocks.insert(1, as_text_table(cols, rows))
    if report is not None:
        report.add_text("Simulated control", intro)
        report.add_table("Summary", cols, rows)
    return "\n\n".join(blocks)


EXAMPLES = [
    Example("rpc-files", "Read the five bundled vendor RPC files and describe them", run_files),
    Example("rpc-round-trip", "RPC project/localise round trip over each image", run_round_trip),
    Example("rpc-bias", "RPC bias compensation with 4 simulated control points", run_bias),
]
