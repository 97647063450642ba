"""HTML report of the residual-grid evaluation of a block (the study's figures).

:func:`grid_study_report` takes the results of
:func:`photogeom.calibration.run_study` (or of the same steps on a real block: a dict with
``fit``, ``refit``, ``grids``, ``evaluation`` and optionally ``sweep``) and writes one
self-contained HTML file with:

* the mean residual vectors over the sensor before and after the correction (the study's
  Figures 7 and 9): residuals of all images averaged in cells of the sensor;
* one image's residuals and its fitted grid, exaggerated (Figure 8);
* the step against the grid size, before and after (Figure 10), also on re-matched
  observations when the results have them;
* the normalised cost (CPU time of the grid fit and the correction) and accuracy of every
  spacing with the chosen one (Figure 13);
* the step per model before and after (Figure 14);
* tables: residual RMS and mean length, steps (also re-matched), check points (X, Y, Z and
  3D) and, for a simulated block, every tie point against the truth, published numbers
  beside ours;
* the notes of the re-adjustment (``notes`` of the result when given, in the caller's
  words, else ``refit.notes``): why its sigma0 is over the chain's effective redundancy or
  its own, and that its standard deviations are in-sample.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..calibration.blocks import block_residuals
from .format import fmt_redundancy, fmt_sigma0
from .html import Report
from .plots import CLIPPED_COLOUR, ArrowScale, arrow_scale, plain

__all__ = ["PUBLISHED", "grid_settings", "grid_study_report", "sensor_mean_residuals"]

#: A Block table cell of an adjustment this report did not run (a block read as adjusted).
NOT_ADJUSTED = "n/a (read as adjusted)"

#: The study's published numbers (05-residual-grid.md).
PUBLISHED = {
    "ILCE-7RM2": ("25 -> 10 (one model)", "100", "200 px (7 of 11)"),
    "FC6310": ("3.2 -> 2.7 (mean)", "70", "150 px (7 of 10)"),
    "FC300S": ("1.4 -> 1.2 (mean)", "70", "150 px (2 of 5)"),
}


def sensor_mean_residuals(block, cells: tuple[int, int] = (12, 8)):
    """Mean tie-point residual vector per sensor cell over the images of the first image's
    size (a block of several cameras: the images of other sizes are left out, their pixels
    lie on another sensor).

    Returns ``(centres (k, 2), mean residuals (k, 2), counts (k,))`` for the cells holding
    observations; pixels.
    """
    sizes = block.image_sizes()
    w, h = sizes[0]
    same = np.all(sizes == sizes[0], axis=1)  # the images of the first image's size only
    per = [v for v, s in zip(block_residuals(block).values(), same.tolist(), strict=True) if s]
    uv = np.concatenate([v[0] for v in per])
    r = np.concatenate([v[1] for v in per])
    nx, ny = cells
    ix = np.clip((uv[:, 0] / w * nx).astype(int), 0, nx - 1)
    iy = np.clip((uv[:, 1] / h * ny).astype(int), 0, ny - 1)
    k = iy * nx + ix
    cnt = np.bincount(k, minlength=nx * ny)
    sx = np.bincount(k, weights=r[:, 0], minlength=nx * ny)
    sy = np.bincount(k, weights=r[:, 1], minlength=nx * ny)
    ok = cnt > 0
    gx, gy = np.meshgrid((np.arange(nx) + 0.5) * w / nx, (np.arange(ny) + 0.5) * h / ny)
    centres = np.column_stack([gx.ravel(), gy.ravel()])[ok]
    mean = np.column_stack([sx[ok], sy[ok]]) / cnt[ok, None]
    return centres, mean, cnt[ok]


def _quiver(ax, xy, v, scale: ArrowScale | None, size, title: str, color="#1f5fa8") -> None:
    """Vectors (px) at their positions on an image, exaggerated, with a scale arrow.

    The scale follows the 90th percentile of the lengths
    (:func:`~photogeom.report.plots.arrow_scale`: at most 7.5 % of the width, the longest
    drawn arrow at most 15 %): vectors longer than 3 times it (blunders, cells or nodes of
    little support) are drawn clipped in :data:`~photogeom.report.plots.CLIPPED_COLOUR`, at
    most :data:`~photogeom.report.plots.MAX_ARROWS` are drawn (the longest always), and the
    title says how many of each. With ``scale`` (from :func:`arrow_scale` with these
    vectors as ``drawn_too``) they are drawn at its exaggeration and clipping length
    instead.
    """
    w, h = size
    v = np.asarray(v, dtype=float).reshape(-1, 2)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    notes = []
    sc = arrow_scale(v, 0.5 * w) if scale is None else scale.applied_to(v)
    k, L = sc.factor, sc.key
    finite = int(np.isfinite(np.hypot(v[:, 0], v[:, 1])).sum())
    v = sc.drawn(v)
    show, clipped = sc.shown, sc.clipped
    if clipped.any():
        notes.append(f"{int(clipped.sum())} longer than {sc.clip:.3g} px clipped (orange)")
    if show.sum() < finite:
        notes.append(f"{int(show.sum())} of {finite} shown")
    for sel, colour in ((show & ~clipped, color), (show & clipped, CLIPPED_COLOUR)):
        if colour == CLIPPED_COLOUR and not sel.any():
            continue
        ax.quiver(
            xy[sel, 0],
            xy[sel, 1],
            v[sel, 0] * k,
            v[sel, 1] * k,  # v down the image: the axis is inverted, so down on the page too
            angles="xy",
            scale_units="xy",
            scale=1,
            color=colour,
            width=0.003,
        )
    if L > 0:
        ax.quiver(
            [0.05 * w],
            [1.06 * h],
            [L * k],
            [0],
            angles="xy",
            scale_units="xy",
            scale=1,
            color="k",
            width=0.004,
        )
        ax.text(0.05 * w, 1.1 * h, f"{L:g} px", fontsize=8)
    if notes:
        title = f"{title}\n{'; '.join(notes)}"
    ax.set_xlim(-0.02 * w, 1.02 * w)
    ax.set_ylim(1.15 * h, -0.02 * h)
    ax.set_aspect("equal")
    ax.set_title(plain(title), fontsize=9)
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")


def _fig_sensor(before, after) -> Figure:
    fig = Figure(figsize=(10, 4))
    size = tuple(before.image_sizes()[0])
    # both panels at the scale of the residuals before the correction (90th percentile;
    # a cell of few observations with a long mean is clipped, not the scale of all others)
    (cb, mb, _), (ca, ma, _) = sensor_mean_residuals(before), sensor_mean_residuals(after)
    scale = arrow_scale(mb, 0.5 * size[0], drawn_too=ma)
    for ax, (c, m), t in zip(
        fig.subplots(1, 2),
        ((cb, mb), (ca, ma)),
        ("before (Fig. 7)", "after the correction (Fig. 9)"),
        strict=True,
    ):
        _quiver(ax, c, m, scale, size, f"mean residual vectors, {t} (same scale)")
    return fig


def _every(step: int) -> str:
    """"every node", "every 2nd node", "every 3rd node", "every 11th node", ..."""
    if step == 1:
        return "every node"
    last = {1: "st", 2: "nd", 3: "rd"}.get(step % 10, "th")
    return f"every {step}{'th' if 11 <= step % 100 <= 13 else last} node"


def _fig_image(block, grids, image_id) -> Figure:
    per = block_residuals(block)
    uv, r = per[image_id]
    g = grids[image_id]
    fig = Figure(figsize=(10, 4))
    a1, a2 = fig.subplots(1, 2)
    size = g.image_size
    _quiver(
        a1, uv, r, None, size, f"image {image_id}: tie-point residuals, exaggerated (Fig. 8)"
    )
    u, v = g.layout.node_coordinates()
    nodes = np.column_stack([u.ravel(), v.ravel()])
    step = max(1, int(np.ceil(max(g.layout.shape) / 25)))  # at most ~25 arrows per side
    sel = np.zeros(g.layout.shape, bool)
    sel[::step, ::step] = True
    sel = sel.ravel() & (nodes[:, 0] <= size[0]) & (nodes[:, 1] <= size[1])
    _quiver(
        a2,
        nodes[sel],
        g.nodes.reshape(-1, 2)[sel],
        None,
        size,
        f"fitted grid, {g.spacing:g} px, {_every(step)} (Fig. 8)",
        color="#a01d12",
    )
    return fig


def _fig_sweep(sweep) -> Figure:
    fig = Figure(figsize=(10, 4))
    a1, a2 = fig.subplots(1, 2)
    g = np.asarray(sweep["spacings"])
    step = np.asarray(sweep["step"])
    before = np.asarray(sweep["step_before"])
    a1.plot(g, step.mean(axis=0), "o-", label="after (mean over models)")
    if sweep.get("step_rematched") is not None:
        a1.plot(
            g,
            np.asarray(sweep["step_rematched"]).mean(axis=0),
            "s--",
            label="after, re-matched observations",
        )
    a1.axhline(before.mean(), color="#a01d12", ls="--", label="before")
    a1.set_xscale("log")
    # ticks at the spacings tried, in pixels (the log axis labelled "10^2", "2 x 10^2")
    a1.set_xticks(g, [f"{x:g}" for x in g], fontsize=8)
    a1.minorticks_off()
    a1.set_xlabel("grid spacing (px)")
    a1.set_ylabel("step (GSD)")
    a1.set_title("step against grid size (Fig. 10)", fontsize=9)
    a1.legend(fontsize=8)
    ch = sweep["choice"]
    sn, tn, idx = np.asarray(ch["step_norm"]), np.asarray(ch["time_norm"]), ch["index"]
    # one grey curve per stereo model through its spacings, its own choice (the point
    # closest to the origin) in red; the legend says so (before: no legend)
    n_models = sn.shape[0]
    for m in range(n_models):
        a2.plot(tn[m], sn[m], ".-", color="#9aaabb", lw=0.6,
                label=f"one stereo model ({n_models})" if m == 0 else None)
        a2.plot(tn[m, idx[m]], sn[m, idx[m]], "o", color="#a01d12",
                label="its spacing closest to (0, 0)" if m == 0 else None)
    # each spacing labelled at its own point closest to the origin (where the choice is
    # made), a few points off it; at the mean over the models, the label could stand far
    # from every point of its spacing (models (0, 1) and (1, 0): at (0.5, 0.5))
    d = np.where(np.isfinite(tn) & np.isfinite(sn), np.hypot(tn, sn), np.inf)
    for c, sp in enumerate(g):
        m = int(np.argmin(d[:, c]))
        if np.isfinite(d[m, c]):
            a2.annotate(f"{sp:g} px", (tn[m, c], sn[m, c]), xytext=(3, 3),
                        textcoords="offset points", fontsize=7)  # fmt: skip
    # the cost: the least CPU time of the spacing's timings (sweep_spacings, repeats)
    n = sweep.get("timings", 1)
    least = f", least of {n} timings" if n > 1 else ""
    a2.set_xlabel(f"normalised CPU time (grid fit and correction{least})")
    a2.set_ylabel("normalised step")
    a2.legend(fontsize=8, loc="upper right")
    a2.set_title(f"cost against accuracy; chosen {sweep['spacing']:g} px (Fig. 13)", fontsize=9)
    return fig


def _fixed(x, decimals: int) -> str:
    """``x`` with ``decimals`` decimals ("-" when undefined)."""
    return "-" if x is None or not np.isfinite(x) else f"{float(x):.{decimals}f}"


def _pct(x) -> str:
    """A fraction in per cent with one decimal, as 'grid evaluate' prints it."""
    return "-" if x is None or not np.isfinite(x) else f"{100 * float(x):.1f} %"


def _rematched_step(res) -> str:
    rm = res.get("rematched")
    return f"{rm['mean_step_after']:.2f}" if rm else "-"


def _fig_models(ev) -> Figure:
    keys = [k for k in ev["steps_before"] if k in ev["steps_after"]]
    fig = Figure(figsize=(10, 3.5))
    ax = fig.subplots()
    x = np.arange(len(keys))
    ax.bar(x - 0.2, [ev["steps_before"][k] for k in keys], 0.4, label="before")
    ax.bar(x + 0.2, [ev["steps_after"][k] for k in keys], 0.4, label="after")
    ax.set_xticks(x)
    ax.set_xticklabels([plain(f"{a}-{b}") for a, b in keys], rotation=90, fontsize=7)
    ax.set_xlabel("model pair: the first model's images (a-b)")
    ax.set_ylabel("step (GSD)")
    ax.set_title(
        "step per model pair (first model's images), before and after (Fig. 14)", fontsize=9
    )
    ax.legend(fontsize=8)
    return fig


def _simulated(res: Mapping) -> bool:
    """Whether a result is of a simulated block: ``res["simulated"]`` when given (the
    command line), else a name that is one of the study's cameras (:func:`run_study`)."""
    if "simulated" in res:
        return bool(res["simulated"])
    return str(res.get("preset", "")).split(" (")[0] in PUBLISHED


def grid_settings(grids: Mapping, n_images: int | None = None) -> list[list[str]]:
    """Rows ``[setting, value]`` of a set of grids: spacing (px), nodes, smoothness sigma
    (px) and the images that have a grid.

    Parameters
    ----------
    grids : Mapping
        ``{image id: ResidualGrid}`` (a grid shared by several images counted once).
    n_images : int, optional
        Images of the block, for "K of N" (without: the count of the grids' images).

    Returns
    -------
    list of [str, str]
    """
    gs = list({id(g): g for g in grids.values()}.values())  # a grid per camera: once
    spacings = sorted({float(g.spacing) for g in gs})
    shapes = sorted({tuple(int(n) for n in np.shape(g.nodes)[:2]) for g in gs})
    rows = [
        ["node spacing", " / ".join(f"{x:g}" for x in spacings) + " px"],
        ["nodes per grid (rows x columns)", ", ".join(f"{a} x {b}" for a, b in shapes)],
    ]
    sc = np.asarray([getattr(g, "sigma_constraint", np.nan) for g in gs], dtype=float)
    if np.isfinite(sc).any():
        lo, hi = np.nanmin(sc), np.nanmax(sc)
        vce = any(getattr(g, "vce_iterations", 0) for g in gs)
        rows.append(
            [
                "smoothness sigma",
                (f"{lo:.4g} px" if np.isclose(lo, hi) else f"{lo:.4g} - {hi:.4g} px")
                + (" (variance components)" if vce else ""),
            ]
        )
    of = "" if n_images is None else f" of {n_images}"
    rows.append(["images with a grid", f"{len(grids)}{of}"])
    return rows


def grid_study_report(
    results: Mapping | Sequence[Mapping],
    path: str | os.PathLike,
    *,
    title: str = "Residual grids: evaluation",
) -> Path:
    """Write the HTML report of one or more study results (see the module); returns the path."""
    if isinstance(results, Mapping):
        results = [results]
    rep = Report(title, "Finite-element residual grids after the bundle adjustment")
    summary = []
    simulated = False
    for res in results:
        ev = res["evaluation"]
        name = res.get("preset", "block")
        sim = _simulated(res)
        simulated |= sim
        pub = PUBLISHED.get(str(name).split(" (")[0], ("-", "-", "-")) if sim else ("-",) * 3
        sw = res.get("sweep")
        summary.append(
            [
                name,
                f"{ev['mean_step_before']:.2f} -> {ev['mean_step_after']:.2f}",
                _rematched_step(res),
                pub[0],
                _pct(ev["residuals"]["block"]["reduction_rms"]),
                f"{sw['spacing']:g} px" if sw else "-",
                pub[2],
            ]
        )
    rep.add_table(
        "Ours beside the study",
        [
            "block",
            "step before -> after (GSD)",
            "re-matched: after (GSD)",
            "published step (GSD)",
            "residual RMS reduction",
            "optimal spacing",
            "published optimum",
        ],
        summary,
        note=(
            ("Simulated re-creations (trends), not the study's data. " if simulated else "")
            + "Re-matched: the corrected observations measured again with fresh noise, as "
            "the study matched its corrected images anew (the grids are not credited with the "
            "noise they fitted)."
        ),
    )
    for res in results:
        name = res.get("preset", "block")
        ev = res["evaluation"]
        fit, refit, grids = res["fit"], res["refit"], res["grids"]
        rep.add_heading(str(name))
        rep.add_table(
            "Grids",
            ["setting", "value"],
            grid_settings(grids, fit.block.n_images),
            note="the grids whose correction the tables and figures below evaluate",
        )
        blk = ev["residuals"]["block"]
        # the numbers and rounding 'grid evaluate' prints: px to 4 decimals, GSD to 3,
        # reductions in per cent
        rows = [
            [
                "RMS (px)",
                _fixed(blk["before"]["rms"], 4),
                _fixed(blk["after"]["rms"], 4),
                _pct(blk["reduction_rms"]),
            ],
            [
                "mean length (px)",
                _fixed(blk["before"]["mean_length"], 4),
                _fixed(blk["after"]["mean_length"], 4),
                _pct(blk["reduction_mean_length"]),
            ],
            [
                "mean step (GSD)",
                _fixed(ev["mean_step_before"], 3),
                _fixed(ev["mean_step_after"], 3),
                _pct(ev["step_reduction"]),
            ],
        ]
        # sigma0 and the redundancy it is over, as grid evaluate prints them; none for a
        # block read as adjusted (a block folder keeps no adjustment's statistics)
        adj = ev.get("adjustment") or {}
        if adj.get("before") or adj.get("after"):
            cells = {k: adj.get(k) for k in ("before", "after")}
            rows.append(
                ["sigma0 (unitless)"]
                + [fmt_sigma0(c) if c else NOT_ADJUSTED for c in cells.values()]
                + [""]
            )
            rows.append(
                ["redundancy"]
                + [fmt_redundancy(c) if c else NOT_ADJUSTED for c in cells.values()]
                + [""]
            )
        if res.get("rematched"):
            rm = res["rematched"]
            rows.append(
                [
                    "mean step, re-matched (GSD)",
                    _fixed(rm["mean_step_before"], 3),
                    _fixed(rm["mean_step_after"], 3),
                    _pct(rm["step_reduction"]),
                ]
            )
        for key, what in (("check", "check RMSE"), ("tie", "tie-point RMSE vs truth")):
            before, after = ev.get(f"{key}_before"), ev.get(f"{key}_after")
            if not (before and after):
                continue
            b, a = np.asarray(before["rmse_gsd"]), np.asarray(after["rmse_gsd"])
            rows.append(
                [
                    f"{what} (GSD, 3D)",
                    _fixed(np.linalg.norm(b), 3),
                    _fixed(np.linalg.norm(a), 3),
                    "",
                ]
            )
            # per axis: the numbers 'grid evaluate' prints and writes with --json
            rows.extend(
                [f"{what} {ax} (GSD)", _fixed(x, 3), _fixed(y, 3), ""]
                for ax, x, y in zip("XYZ", b, a)
            )
        left = ev.get("excluded") or []
        rep.add_table(
            "Block",
            ["quantity", "before", "after", "reduction"],
            rows,
            note="reduction: 1 - after / before"
            + (
                f"; left out (no grid, observations uncorrected): {len(left)} image(s): "
                + ", ".join(map(str, left[:20]))
                + (" ..." if len(left) > 20 else "")
                if left
                else ""
            ),
        )
        # why the re-adjustment's sigma0 is over the chain's redundancy or its own, and that
        # its standard deviations are in-sample (the command line passes them in its words)
        notes = res.get("notes")
        if notes is None:
            notes = list(getattr(refit, "notes", ()))
        if notes:
            rep.add_text("Notes of the re-adjustment", "\n\n".join(map(str, notes)), pre=False)
        rep.add_table(
            "Per image",
            [
                "image",
                "RMS before (px)",
                "RMS after (px)",
                "mean length before (px)",
                "mean length after (px)",
            ],
            [
                [
                    str(k),
                    _fixed(v["before"]["rms"], 4),
                    _fixed(v["after"]["rms"], 4),
                    _fixed(v["before"]["mean_length"], 4),
                    _fixed(v["after"]["mean_length"], 4),
                ]
                for k, v in ev["residuals"]["images"].items()
            ],
        )
        rep.add_figure("Mean residual vectors over the sensor", _fig_sensor(fit.block, refit.block))
        first = next(iter(grids))
        rep.add_figure("One image's residuals and fitted grid", _fig_image(fit.block, grids, first))
        if res.get("sweep"):
            rep.add_figure("Grid size", _fig_sweep(res["sweep"]))
        rep.add_figure("Step per model", _fig_models(ev))
    return rep.write(path)
