"""The HTML report of a bundle adjustment (:class:`~photogeom.bundle.BundleFit`).

The report is rendered from a JSON-ready *result record*, :func:`bundle_result_data`: the
summary of ``BundleFit.to_dict()`` plus what the figures need (calibration correlation
matrices, residuals binned over the sensor, the point-precision histogram, the flagged
observations with their residuals). The record is small (it grows with the images, not with
the observations), so it can be saved (``photogeom bundle adjust --result r.json``) and
rendered again later (``photogeom bundle report r.json``) into the same report.

>>> fit = pg.bundle_adjust(block, point_covariance=True)         # doctest: +SKIP
>>> bundle_report(fit).write("bundle.html")                      # doctest: +SKIP
>>> rep = Report("Survey 2026"); add_bundle_fit(rep, fit)         # doctest: +SKIP
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from . import format as F
from .bundle_record import (  # noqa: F401 - the record's names, as before
    _CAL_NAMES,
    _CAL_UNIT,
    _KIND_WORDS,
    _NUMBER,
    _RECORD_ENTRIES,
    MAX_FLAGGED,
    MAX_GROUP_PANELS,
    MAX_ROWS,
    MIN_CELL_COUNT,
    RESULT_FORMAT,
    RESULT_VERSION,
    _flagged,
    _nan,
    _point_histogram,
    _sensor_grid,
    bundle_result_data,
    read_bundle_result,
    write_bundle_result,
)
from .html import Report, _esc, _img_html, _table_html, figure_to_png
from .plots import CLIPPED_COLOUR, arrow_scale, plain

# --- figures -------------------------------------------------------------------------------------


def sensor_grid_figure(grids: list[Mapping]) -> Figure:
    """Mean residual vector per sensor cell, one panel per camera group, arrows exaggerated
    by a common factor with a scale arrow of their true length (pixels).

    The factor follows the 90th percentile of the lengths of the cells with at least
    :data:`MIN_CELL_COUNT` observations over all panels (:func:`~.plots.arrow_scale`: that
    length is drawn at most 1.2 cells long, the longest drawn arrow at most 2.4); means
    longer than 3 times it (a systematic corner, or a cell of few observations with a
    blunder) are drawn clipped to it in :data:`~.plots.CLIPPED_COLOUR` and counted in the
    panel's title.
    """
    n = len(grids)
    cols = min(n, 2)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(6.2 * cols, 4.9 * rows), dpi=110)
    means, strong_rows, cells = [], [], []
    for g in grids:
        m = np.array([[_nan(a), _nan(b)] for a, b in g["mean"]]).reshape(-1, 2)
        means.append(m)
        strong_rows.append(np.isfinite(m).all(axis=1) & (np.asarray(g["count"]) >= MIN_CELL_COUNT))
        cells.append(min(g["width"] / g["nx"], g["height"] / g["ny"]))
    # one scale for all panels, from the well-observed cells (with none, from all): an
    # extent of 8 cells of the smallest, the typical mean drawn at most 1.2 cells long, the
    # longest (clipped) at most 2.4
    ref = np.concatenate([m[s] for m, s in zip(means, strong_rows, strict=True)])
    if not len(ref):
        ref = np.concatenate(means)
    everything = np.concatenate(means)
    base = arrow_scale(ref, 8.0 * min(cells), drawn_too=everything) if len(ref) else None
    for k, g in enumerate(grids):
        ax = fig.add_subplot(rows, cols, k + 1)
        w, h, nx, ny = g["width"], g["height"], g["nx"], g["ny"]
        cw, ch = w / nx, h / ny
        m = means[k]
        cnt = np.asarray(g["count"])
        iy, ix = np.divmod(np.arange(nx * ny), nx)
        xc = (ix + 0.5) * cw - 0.5
        yc = (iy + 0.5) * ch - 0.5
        ok = np.isfinite(m).all(axis=1)
        sc = base.applied_to(m) if base is not None else None
        factor = sc.factor if sc is not None else 1.0
        drawn = sc.drawn(m) if sc is not None else m
        clipped = sc.clipped if sc is not None else np.zeros(len(m), dtype=bool)
        for x in np.arange(nx + 1) * cw - 0.5:
            ax.axvline(x, color="#e3e8ee", lw=0.6, zorder=1)
        for y in np.arange(ny + 1) * ch - 0.5:
            ax.axhline(y, color="#e3e8ee", lw=0.6, zorder=1)
        ax.plot(xc[ok], yc[ok], ".", color="#8a99a8", ms=2, zorder=2)
        strong = ok & (cnt >= MIN_CELL_COUNT) & ~clipped
        weak = ok & (cnt < MIN_CELL_COUNT) & ~clipped
        q = None
        for sel, colour in ((strong, "#1f5fa8"), (weak, "#a9bcd0"), (clipped, CLIPPED_COLOUR)):
            if sel.any():
                qq = ax.quiver(
                    xc[sel],
                    yc[sel],
                    drawn[sel, 0],
                    drawn[sel, 1],
                    angles="xy",
                    scale_units="xy",
                    scale=1.0 / factor,
                    color=colour,
                    width=0.006,
                    zorder=3,
                )
                q = q or qq
        if q is not None and sc is not None and sc.key > 0:
            key = sc.key
            ax.quiverkey(
                q,
                X=0.70,
                Y=1.03,
                U=key,
                label=f"{key:g} px",
                labelpos="E",
                coordinates="axes",
                color="black",
            )
        ax.add_patch(_rect(w, h))
        ax.set_xlim(-0.5 - 0.02 * w, w - 0.5 + 0.02 * w)
        ax.set_ylim(h - 0.5 + 0.02 * h, -0.5 - 0.02 * h)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("u (column) [px]")
        ax.set_ylabel("v (row) [px]")
        ex = f"{factor:,.0f}" if factor >= 10 else f"{factor:.3g}"
        ax.set_title(
            plain(
                f"{g['label']}: {g['n_observations']} obs. in {g['n_images']} images, RMS "
                f"{g['rms']:.3g} px\nmean v per {nx} x {ny} cell, arrows x{ex}"
                + (
                    f"; {int(clipped.sum())} longer than {sc.clip:.3g} px clipped (orange)"
                    if clipped.any()
                    else ""
                )
            ),
            fontsize=9,
            loc="left",
        )
    fig.tight_layout()
    return fig


def _rect(w, h):
    from matplotlib.patches import Rectangle

    return Rectangle((-0.5, -0.5), w, h, fill=False, ec="#22364d", lw=1.0, zorder=4)


def correlation_figure(names, R, threshold: float, title: str) -> Figure:
    """Heat map of a correlation matrix with the values written in; |rho| above the
    threshold boxed in red."""
    R = np.array([[_nan(x) for x in row] for row in R], dtype=float).reshape(len(names), -1)
    k = len(names)
    size = 1.2 + 0.42 * k
    fig = Figure(figsize=(size + 1.0, size), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    im = ax.imshow(R, vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(k), [plain(n) for n in names])
    ax.set_yticks(range(k), [plain(n) for n in names])
    ax.tick_params(length=0)
    for i in range(k):
        for j in range(k):
            if i == j or not np.isfinite(R[i, j]):
                continue
            hi = abs(R[i, j]) > threshold
            ax.text(
                j,
                i,
                f"{R[i, j]:.2f}",
                ha="center",
                va="center",
                fontsize=7 if k > 7 else 8,
                fontweight="bold" if hi else "normal",
                color="white" if abs(R[i, j]) > 0.6 else "#1d2733",
            )
            if hi:
                ax.add_patch(_box(j, i))
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="correlation")
    ax.set_title(plain(f"{title}\n|rho| > {threshold:g} boxed"), fontsize=9, loc="left")
    fig.tight_layout()
    return fig


def _box(j, i):
    from matplotlib.patches import Rectangle

    return Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec="#c0392b", lw=2.0)


def image_rms_figure(images: list[Mapping], overall: float) -> Figure:
    """RMS image residual per image (pixels), in block order."""
    ids = [str(r["id"]) for r in images]
    rms = np.array([_nan(r["rms_px"]) for r in images])
    n = len(ids)
    fig = Figure(figsize=(9.5, 3.2), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    x = np.arange(n)
    if n <= 300:
        ax.bar(x, rms, width=0.8, color="#1f5fa8")
    else:
        ax.plot(x, rms, lw=0.8, color="#1f5fa8")
    if math.isfinite(overall):
        ax.axhline(overall, color="#c0392b", lw=1, ls="--", label=f"all images: {overall:.3g} px")
        ax.legend(fontsize=8, loc="upper right")
    if n <= 40:
        ax.set_xticks(
            x,
            [plain(t) for t in ids],
            rotation=90 if max(map(len, ids), default=0) > 3 else 0,
            fontsize=8,
        )
        ax.set_xlabel("image id")
    else:
        ax.set_xlabel("image (block order)")
    ax.set_ylabel("RMS residual [px]")
    ax.set_xlim(-0.8, n - 0.2)
    ax.grid(True, axis="y", color="#dddddd", lw=0.6)
    fig.tight_layout()
    return fig


def convergence_figure(history) -> Figure:
    """Cost v'Pv after each accepted step (log scale) and the relative decrease of each step
    (log scale)."""
    from matplotlib.ticker import FuncFormatter

    c = np.array([_nan(x) for x in history])
    fig = Figure(figsize=(9.5, 3.2), dpi=110)
    a1 = fig.add_subplot(1, 2, 1)
    a2 = fig.add_subplot(1, 2, 2)
    it = np.arange(c.size)
    pos = c > 0
    a1.semilogy(it[pos], c[pos], "o-", color="#1f5fa8", ms=4)
    fmt = FuncFormatter(lambda y, _: f"{y:.6g}")  # plain numbers (no mathtext: faster)
    for ax in (a1, a2):
        ax.yaxis.set_major_formatter(fmt)
        ax.yaxis.set_minor_formatter(FuncFormatter(lambda y, _: ""))
    if pos.any() and c[pos].max() < 10 * c[pos].min():
        a1.yaxis.set_minor_formatter(fmt)  # less than a decade: label the minor ticks
        a1.tick_params(axis="y", which="minor", labelsize=7)
    a1.set_xlabel("iteration (0 = start)")
    a1.set_ylabel("cost v'Pv")
    a1.set_title("cost", fontsize=9, loc="left")
    if c.size > 1:
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = (c[:-1] - c[1:]) / c[:-1]
        ok = rel > 0
        a2.semilogy(it[1:][ok], rel[ok], "s-", color="#2e8b57", ms=4)
    a2.yaxis.set_major_formatter(FuncFormatter(lambda y, _: f"{y:.0e}"))
    a2.set_xlabel("iteration")
    a2.set_ylabel("relative decrease")
    a2.set_title("relative decrease of each step", fontsize=9, loc="left")
    for ax in (a1, a2):
        ax.xaxis.get_major_locator().set_params(integer=True)
        ax.grid(True, color="#e3e8ee", lw=0.6)
    fig.tight_layout()
    return fig


def point_precision_figure(hist: Mapping, unit: str) -> Figure:
    """Histograms of the points' standard deviations in X, Y and Z."""
    e = np.asarray(hist["edges"])
    fig = Figure(figsize=(6.4, 3.4), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    for a, colour in zip("XYZ", ("#1f5fa8", "#2e8b57", "#c0392b")):
        ax.stairs(hist["counts"][a], e, color=colour, lw=1.4, label=f"s{a}")
    ax.set_xlabel(plain(f"standard deviation [{unit}]"))
    ax.set_ylabel("points")
    ax.legend(fontsize=8)
    ax.grid(True, color="#e3e8ee", lw=0.6)
    fig.tight_layout()
    return fig


# --- the report ----------------------------------------------------------------------------------


def _f(x, digits: int = 4) -> str:
    return F.fmt_stat(_nan(x), digits)


def _gsd(x) -> str:
    """Two decimals ("-" when undefined): lengths in GSD and the critical value of the
    w-test, as the printed summary gives them."""
    return F.fmt_fixed(_nan(x), 2)


def _std(x) -> str:
    return F.fmt_std(_nan(x))


def _val(v, s) -> str:
    return F.fmt_value(_nan(v), None if s is None else _nan(s))


def _pm(v, s) -> str:
    """``value ± std``; ``value (fixed)`` for a zero std. dev."""
    sv = _nan(s)
    if sv == 0.0:
        return f"{F.fmt_value(_nan(v))} (fixed)"
    return f"{_val(v, s)} ± {_std(s)}"


def _crs_rows(d: Mapping) -> list[list[str]]:
    """Rows naming the CRS of the object coordinates and of the GNSS positions."""
    rows = []
    if d.get("crs"):
        rows.append(["object coordinates", str(d.get("crs_name") or d["crs"])])
    g = d.get("georeferencing")
    if g:
        rows.append(
            [
                "GNSS positions",
                f"{g['n_gnss']} converted from {g['gnss_crs_name']} into the block's system; "
                "adjusted projection centres in that CRS in the result record "
                "(images[].position_gnss_crs)",
            ]
        )
    return rows


def _summary_rows(d: Mapping) -> list[list[str]]:
    c = d["chi2"]
    blk = d["block"]
    solver = d.get("solver") or {}
    test = "-"
    if c.get("passed") is not None:
        test = (
            f"{'passed' if c['passed'] else 'FAILED'}: {_f(c['statistic'], 6)} in "
            f"[{_f(c['lower'], 6)}, {_f(c['upper'], 6)}] (two-sided, alpha {c['alpha']}), "
            f"p = {_f(c['p_value'], 3)}"
        )
    return [
        [
            "block",
            f"{blk['n_camera_groups']} camera group(s), {blk['n_images']} images, "
            f"{blk['n_points']} points ({blk['n_tie']} tie, {blk['n_control']} control, "
            f"{blk['n_check']} check), {blk['n_image_observations']} image observations",
        ],
        [
            "datum observations",
            ", ".join(
                [
                    s
                    for s, ok in (
                        ("control points", blk["n_control"] > 0),
                        ("GNSS", blk["has_gnss"]),
                        ("IMU", blk["has_imu"]),
                    )
                    if ok
                ]
            )
            or "none (free network)",
        ],
        *([["adjusted by", str(d["command"])]] if d.get("command") else []),
        *_crs_rows(d),
        # sigma0, the RMS residual, the IMU residuals, the critical value and |w| with the
        # rounding of the printed summary (BundleFit.summary), so both show the same digits
        ["sigma0 a posteriori", F.fmt_fixed(_nan(d["sigma0"]), 4)],
        ["sigma0 a priori", _f(d["sigma0_prior"])],
        ["observations / unknowns", f"{d['n_observations']} / {d['n_unknowns']}"],
        ["redundancy r", str(d["redundancy"])],
        ["chi-square test of v'Pv / sigma0_prior^2", test],
        ["RMS image residual", f"{F.fmt_fixed(_nan(d['rmse_px']), 3)} px"],
        *_orientation_residual_rows(d),
        ["mean GSD", f"{_f(d['gsd'])} {d['unit']}/px"],
        [
            "convergence",
            (f"{d['message']}" if d["converged"] else f"NOT CONVERGED ({d['message']})")
            + f" after {d['iterations']} iteration(s)",
        ],
        # seconds to 2 decimals as the printed summary (3 significant digits wrote 1.5e+03)
        ["time", f"{F.fmt_fixed(_nan(d['elapsed_s']), 2)} s"],
        [
            "solver",
            f"{solver.get('backend', '?')}, reduced camera system "
            f"{solver.get('reduced_system_size', '?')} unknowns, "
            f"{solver.get('reduced_system_nonzeros', '?')} non-zeros; loss "
            f"{solver.get('loss', '?')}"
            + (
                f" (scale {_f(solver['loss_scale'])} a-priori sigmas)"
                if solver.get("loss_scale") is not None
                else ""
            ),
        ],
    ]


def _a_priori_section(d: Mapping) -> str:
    """The stochastic model: the a-priori standard deviations of each group of observations
    (median, least and largest, with the unit)."""
    rows = [
        [
            r["observations"],
            str(r["n"]),
            _f(r["median"]),
            _f(r["min"]) if r["min"] == r["max"] else f"{_f(r['min'])} - {_f(r['max'])}",
            r["unit"],
        ]
        for r in d["a_priori"]
    ]
    return _table_html(
        ["observations", "n", "sigma (median)", "range", "unit"],
        rows,
        note="as given with the block (before the adjustment); each observation weighs "
        "sigma0_prior^2 / sigma^2",
        text_cols={0, 4},
    )


def _orientation_residual_rows(d: Mapping) -> list[list[str]]:
    """RMS per axis of the GNSS and IMU residuals (adjusted minus observed), if any."""
    orr = d.get("orientation_residual_rms") or {}
    rows = []
    if orr.get("gnss") is not None:
        g = orr["gnss"]
        rows.append(
            [
                f"RMS GNSS residual (adjusted - GNSS, {orr['gnss_images']} images)",
                f"X0 {_f(g[0])}, Y0 {_f(g[1])}, Z0 {_f(g[2])} {d['unit']}",
            ]
        )
    if orr.get("imu") is not None:
        a = orr["imu"]
        rows.append(
            [
                f"RMS IMU residual (adjusted - IMU, {orr['imu_images']} images)",
                f"omega {_f(a[0], 3)}, phi {_f(a[1], 3)}, kappa {_f(a[2], 3)} {d['angle_unit']}",
            ]
        )
    return rows


def _calibration_section(d: Mapping, max_rows: int) -> str:
    cal, cstd = d["calibration"], d["calibration_std"]
    groups = list(cal)
    thr = float(d.get("correlation_threshold", 0.9))
    parts: list[str] = []
    if len(groups) <= MAX_GROUP_PANELS:
        per_image = d.get("image_calibration") or {}
        for g in groups:
            rows = []
            iv = per_image.get(str(g), {})
            for n in _CAL_NAMES:
                s = cstd[g].get(n)
                free = s is not None
                std = _std(s) if free else "fixed"
                if n in iv:  # the group's value is held, each image's offset estimated
                    std = (
                        f"per image: offsets RMS {_f(iv[n]['rms_offset'], 3)}, "
                        f"std. dev. RMS {_f(iv[n]['rms_std'], 3)}"
                    )
                rows.append([n, _val(cal[g][n], s), std, _CAL_UNIT[n]])
            table = f"<h4>camera {_esc(g)}</h4>" + _table_html(
                ["parameter", "value", "std. dev.", "unit"],
                rows,
                text_cols={2, 3},
                note="f, cx, cy, b1, b2 in pixels (cx, cy from the image centre); K, P "
                "dimensionless (Metashape frame model)"
                + (
                    "; 'per image': the image's value is this one plus its offset (result "
                    "record: images[].f_offset, sf_offset, ...)"
                    if iv
                    else ""
                ),
            )
            corr = d["calibration_correlation"].get(g)
            fig = ""
            if corr and len(corr["names"]) >= 2:
                fig = _img_html(
                    figure_to_png(
                        correlation_figure(
                            corr["names"], corr["matrix"], thr, f"camera {g}: correlations"
                        )
                    ),
                    f"calibration correlations of camera {g}",
                    None,
                )
            parts.append(f'<div class="grid"><div>{table}</div><div>{fig}</div></div>')
    else:
        free = [n for n in _CAL_NAMES if any(cstd[g].get(n) is not None for g in groups)]
        shown = groups[:max_rows]
        rows = [[g, *[_pm(cal[g][n], cstd[g].get(n)) for n in free]] for g in shown]
        parts.append(
            _table_html(
                ["camera", *[f"{n} [{_CAL_UNIT[n]}]" for n in free]],
                rows,
                numeric_cols=set(range(1, len(free) + 1)),
                note=f"{len(shown)} of {len(groups)} camera groups (block order); "
                "value ± std. dev. of the free parameters; the result record holds "
                "all",
            )
        )
    high = d.get("high_correlations") or []
    if high:
        rows = [[str(g), a, b, f"{r:+.3f}"] for g, a, b, r in high[:max_rows]]
        parts.append(
            f"<h4>Correlations with |rho| &gt; {thr:g} ({len(high)})</h4>"
            + _table_html(
                ["camera", "parameter", "parameter", "rho"],
                rows,
                flags=[[False, False, False, True]] * len(rows),
                text_cols={1, 2},
            )
            + '<p class="note">These parameters are not separated well by the block\'s '
            "geometry: fix one of them, or add control, GNSS, oblique images or height "
            "differences.</p>"
        )
    return "".join(parts)


def _exterior_section(d: Mapping, max_rows: int) -> str:
    imgs = d["images"]
    au, u = d["angle_unit"], d["unit"]
    order = list(range(len(imgs)))
    note = f"all {len(imgs)} images in block order"
    if len(imgs) > max_rows:
        order = sorted(
            order,
            key=lambda k: (
                -_nan(imgs[k]["rms_px"]) if math.isfinite(_nan(imgs[k]["rms_px"])) else math.inf
            ),
        )[:max_rows]
        note = (
            f"the {max_rows} of {len(imgs)} images with the largest RMS residual (largest "
            "first); the result record holds all"
        )
    names = ("X0", "Y0", "Z0", "omega", "phi", "kappa")
    cams = len({str(r.get("camera", "")) for r in imgs}) > 1  # a camera column when useful
    cols = [
        "image",
        *(["camera"] if cams else []),
        *[f"{n} ± s [{u if k < 3 else au}]" for k, n in enumerate(names)],
        "obs.",
        "RMS [px]",
    ]
    rows = []
    for k in order:
        r = imgs[k]
        rows.append(
            [
                str(r["id"]),
                *([str(r.get("camera", ""))] if cams else []),
                *[_pm(r[n], r[f"s{n}"]) for n in names],
                str(r.get("n_obs", "")),
                _f(r["rms_px"], 3),
            ]
        )
    c0 = 2 if cams else 1
    table = _table_html(
        cols,
        rows,
        text_cols={1} if cams else None,
        numeric_cols=set(range(c0, c0 + 6)),
        note=note + '; value ± a-posteriori std. dev. ("fixed": held at its value); RMS of '
        "the image residual lengths of the image's adjusted observations",
    )
    return f'<div style="overflow-x:auto">{table}</div>'


def _positions_section(d: Mapping, max_rows: int) -> str:
    """The adjusted projection centres in the CRS of the GNSS positions."""
    g = d["georeferencing"]
    imgs = d["images"][:max_rows]
    angular = bool(g.get("angular"))
    names = g.get("axes") or ["x", "y", "z"]
    decimals = (9, 9, 4) if angular else (4, 4, 4)
    rows = [
        [
            str(r["id"]),
            *("-" if v is None else f"{v:.{k}f}" for v, k in zip(r["position_gnss_crs"], decimals)),
        ]
        for r in imgs
    ]
    more = len(d["images"]) > max_rows
    note = (
        f"Adjusted projection centres converted from the block's system ({d.get('crs_name')}) "
        f"to {g['gnss_crs_name']}, x/longitude first"
        + (f"; the first {max_rows} of {len(d['images'])} images" if more else "")
        + "."
    )
    return _table_html(["image", *names], rows, note=note)


def _points_section(d: Mapping) -> str:
    u = d["unit"]
    gsd = _nan(d["gsd"])
    parts = []
    for key, title, conv in (
        ("control", "Control points", "adjusted minus surveyed (in the adjustment)"),
        (
            "check",
            "Check points",
            "triangulated from their image observations with the "
            "adjusted cameras, minus surveyed (not in the adjustment)",
        ),
    ):
        c = d.get(key) or {}
        ids = c.get("ids") or []
        if not ids:
            continue
        if "similarity" in (c.get("convention") or ""):  # a free network's check points
            conv = c["convention"] + " (not in the adjustment)"
        err = np.array([[_nan(x) for x in row] for row in c["errors"]], dtype=float)
        length = np.sqrt((err**2).sum(axis=1))
        rows = [
            [str(i), *[F.fmt_fixed(x, 4) for x in e], F.fmt_fixed(n, 4), F.fmt_fixed(n / gsd, 2)]
            for i, e, n in zip(ids, err, length)
        ]
        rm, rg = c["rmse"], c["rmse_gsd"]
        rows.append(
            [
                "RMSE",
                *[F.fmt_fixed(_nan(x), 4) for x in rm],
                F.fmt_fixed(float(np.sqrt(np.sum(np.square([_nan(x) for x in rm])))), 4),
                F.fmt_fixed(float(np.sqrt(np.sum(np.square([_nan(x) for x in rg])))), 2),
            ]
        )
        parts.append(
            f"<h4>{title} ({len(ids)})</h4>"
            + _table_html(
                ["point", f"dX [{u}]", f"dY [{u}]", f"dZ [{u}]", f"|d| [{u}]", "|d| [GSD]"], rows
            )
            # the RMSE as the printed summary gives it: 4 significant digits, GSD 2 decimals
            + f'<p class="note">{_esc(conv)}; RMSE X {_f(rm[0])}, Y {_f(rm[1])}, '
            f"Z {_f(rm[2])} {_esc(u)} ({_gsd(rg[0])}, {_gsd(rg[1])}, {_gsd(rg[2])} GSD; "
            f"GSD {_f(gsd)} {_esc(u)}/px)</p>"
        )
    return "".join(parts)


def _flagged_section(d: Mapping, max_rows: int) -> str:
    sn = d.get("snooping")
    if sn is None:
        return '<p class="note">Data snooping was not run (snooping=False).</p>'
    fl = d.get("flagged") or []
    n = int(d.get("n_flagged", len(fl)))
    head = (
        f"<p>Baarda's w-test per image observation (the larger |w| of u and v), "
        f"alpha {sn['alpha']} per test, critical value {_gsd(sn['critical_value'])}: "
        f"<strong>{n}</strong> observation(s) flagged. Flagged observations are listed, "
        "not removed: the largest |w| is the most likely blunder; remove it and adjust "
        "again.</p>"
    )
    if not fl:
        return head
    shown = fl[:max_rows]
    rows = [
        [
            str(r["image"]),
            str(r["point"]),
            f"{r['w']:.1f}",
            F.fmt_fixed(_nan(r["v"][0]), 3),
            F.fmt_fixed(_nan(r["v"][1]), 3),
            _f(r["sigma"], 3),
        ]
        for r in shown
    ]
    return head + _table_html(
        ["image", "point", "|w|", "v_u [px]", "v_v [px]", "sigma [px]"],
        rows,
        flags=[[False, False, True, False, False, False]] * len(rows),
        note=(f"the {len(shown)} largest of {n}" if n > len(shown) else f"all {n}")
        + "; v = computed - observed",
    )


def _poorly_controlled_section(d: Mapping, max_rows: int) -> str:
    """The observations a blunder could hide in (redundancy number below 0.1), with their
    redundancy numbers and minimal detectable biases; empty for a record without them."""
    from ..adjust.snooping import POORLY_CONTROLLED, POWER

    sn = d.get("snooping")
    if sn is None or "poorly_controlled" not in d:  # no test, or a record without the list
        return ""
    pc = d["poorly_controlled"] or []
    n = int(d.get("n_poorly_controlled", len(pc)))
    head = (
        f"<p>Observations with a redundancy number r below {POORLY_CONTROLLED:g} in u or v: "
        f"<strong>{n}</strong>. A gross error there is largely absorbed by the parameters "
        "(e.g. along the base of a point seen in two images) and may pass the w-test; the "
        f"minimal detectable bias (MDB) is the error the test finds with probability "
        f"{POWER:.0%} at alpha {sn['alpha']}. Measure those points in more images.</p>"
    )
    if not pc:
        return head
    shown = pc[:max_rows]

    def mdb(x, r, sigma) -> list[str]:
        # an infinite MDB (r = 0: no error shows in the residual) is null in the record
        x = _nan(x)
        if not math.isfinite(x) and math.isfinite(_nan(r)):
            return ["undetectable", "undetectable"]
        return [F.fmt_fixed(x, 1), F.fmt_fixed(x * _nan(sigma), 2)]

    rows = [
        [
            str(r["image"]),
            str(r["point"]),
            F.fmt_fixed(_nan(r["r"][0]), 3),
            F.fmt_fixed(_nan(r["r"][1]), 3),
            *mdb(r["mdb"][0], r["r"][0], r["sigma"]),
            *mdb(r["mdb"][1], r["r"][1], r["sigma"]),
        ]
        for r in shown
    ]
    return head + _table_html(
        ["image", "point", "r_u", "r_v", "MDB_u [sigma]", "MDB_u [px]", "MDB_v [sigma]",
         "MDB_v [px]"],
        rows,
        note=(f"the {len(shown)} least controlled of {n}" if n > len(shown) else f"all {n}")
        + " (smallest r first); r: redundancy number, the share of an error of the "
        "observation that shows in its residual (unitless); MDB in a-priori standard "
        "deviations (sigma) and in pixels",
    )  # fmt: skip


def _variance_section(vc: Mapping) -> str:
    f = vc.get("factors") or {}
    red = vc.get("redundancy") or {}
    held = vc.get("not_estimated") or {}
    rows = [
        [
            k + (" (not estimated: a-priori sigmas)" if k in held else ""),
            F.fmt_fixed(_nan(v), 4),
            F.fmt_fixed(_nan(v) ** 2, 4),
            F.fmt_fixed(_nan(red.get(k)), 1),
        ]
        for k, v in f.items()
    ]
    conv = "converged" if vc.get("converged") else "NOT converged"
    return _table_html(
        ["observation group", "sigma factor", "variance factor", "redundancy"],
        rows,
        note=f"{_esc(vc.get('meaning', ''))}; iterated estimation {conv} after "
        f"{vc.get('rounds', '?')} round(s)",
    )


#: The notes' pointer to the result's key (``BundleFit`` notes), where the report has the
#: section: its title, and the key of the record for all of them.
_POOR_KEY = "they are listed in snooping['poorly_controlled']:"
_POOR_SECTION = (
    "they are listed under Poorly controlled observations (all of them in the result "
    "record: snooping.poorly_controlled):"
)


def _report_words(note: str, poor_section: bool) -> str:
    """A note of the record in the report's words: the poorly controlled observations are
    pointed to in their section (when the report has it), not in a Python mapping."""
    if poor_section:
        return note.replace(_POOR_KEY, _POOR_SECTION)
    return note.replace(
        _POOR_KEY, "they are listed in the result record (snooping.poorly_controlled):"
    )


def add_bundle_result(
    report: Report,
    data: Mapping,
    title: str | None = None,
    *,
    max_rows: int = MAX_ROWS,
) -> None:
    """Add the sections of a bundle adjustment to ``report`` from its result record.

    Sections: summary statistics; the a-priori standard deviations (when the record has
    them); calibration with standard deviations and correlation heat
    map; exterior orientation (the ``max_rows`` images with the largest RMS residual when
    there are more); control and check points; residual vectors binned over the sensor;
    RMS residual per image; point precision (when computed); convergence; flagged
    observations; variance components (when estimated); notes.

    Parameters
    ----------
    report : Report
        The report to add to.
    data : Mapping
        A result record (:func:`bundle_result_data` or :func:`read_bundle_result`).
    title : str, optional
        Chapter heading.
    max_rows : int, default MAX_ROWS
        Rows of the long tables at most.
    """
    d = data
    p = f"{title}: " if title else ""
    report._add(
        3,
        f"{p}Adjustment summary" if title else "Adjustment summary",
        _table_html(["quantity", "value"], _summary_rows(d), cls="stats", header=False)
        + (
            ""
            if d["converged"]
            else '<p class="warn">The iteration did NOT converge; do not trust these numbers.</p>'
        ),
    )
    if d.get("a_priori"):  # records written before it was kept have none
        report._add(3, f"{p}A-priori standard deviations", _a_priori_section(d))
    report._add(3, f"{p}Calibration", _calibration_section(d, max_rows))
    report._add(3, f"{p}Exterior orientation", _exterior_section(d, max_rows))
    if d.get("georeferencing") and d.get("images"):
        g = d["georeferencing"]
        report._add(
            3,
            f"{p}Projection centres in {g['gnss_crs_name']}",
            _positions_section(d, max_rows),
        )
    pts = _points_section(d)
    if pts:
        report._add(3, f"{p}Control and check points", pts)
    if d.get("sensor_grid"):
        report._add(
            3,
            f"{p}Residuals over the sensor",
            _img_html(
                figure_to_png(sensor_grid_figure(d["sensor_grid"])),
                "residuals over the sensor",
                "Mean image residual (computed - observed) of the adjusted observations in each "
                "cell of a regular grid over the image frame; pale arrows: cells with fewer than "
                f"{MIN_CELL_COUNT} observations. A pattern repeated over the frame is a "
                "systematic error the camera model does not absorb.",
            ),
        )
    if d.get("images"):
        report._add(
            3,
            f"{p}Residual RMS per image",
            _img_html(
                figure_to_png(image_rms_figure(d["images"], _nan(d["rmse_px"]))),
                "RMS residual per image",
                "RMS of the image residual lengths of each image's "
                "adjusted observations, in block order.",
            ),
        )
    pp = d.get("point_precision")
    if pp:
        txt = (
            f"{pp['n']} tie and control points; RMS of the standard deviations X "
            f"{_f(pp['rms'][0])}, Y {_f(pp['rms'][1])}, Z {_f(pp['rms'][2])} {d['unit']}; "
            f"median {_f(pp['median'][0])}, {_f(pp['median'][1])}, {_f(pp['median'][2])}; "
            f"largest {_f(pp['max'][0])}, {_f(pp['max'][1])}, {_f(pp['max'][2])}"
        )
        above = sum(pp["above"].values())
        if above:
            txt += f"; {above} value(s) beyond the last bin are counted in it"
        report._add(
            3,
            f"{p}Point precision",
            _img_html(
                figure_to_png(point_precision_figure(pp, d["unit"])),
                "point precision",
                txt + " (marginal a-posteriori standard deviations).",
            ),
        )
    else:
        report._add(
            3,
            f"{p}Point precision",
            '<p class="note">Point covariances were not '
            "computed (bundle_adjust(..., point_covariance=True), or --point-covariance "
            "at the command line).</p>",
        )
    if d.get("cost_history"):
        report._add(
            3,
            f"{p}Convergence",
            _img_html(
                figure_to_png(convergence_figure(d["cost_history"])),
                "convergence",
                f"Cost v'Pv (whitened, robust weights applied) after each accepted "
                f"Levenberg-Marquardt step; {d['message']}."
                + (
                    " With variance components: the last round's iterations (each round "
                    "re-weights the groups and iterates again)."
                    if d.get("variance_components")
                    else ""
                ),
            ),
        )
    report._add(3, f"{p}Flagged observations (w-test)", _flagged_section(d, max_rows))
    poor = _poorly_controlled_section(d, max_rows)
    if poor:
        report._add(3, f"{p}Poorly controlled observations", poor)
    if d.get("variance_components"):
        report._add(3, f"{p}Variance components", _variance_section(d["variance_components"]))
    notes = [_report_words(n, bool(poor)) for n in d.get("notes") or []]
    report._add(
        3,
        f"{p}Notes",
        "".join(f'<p class="note">{_esc(n)}</p>' for n in notes)
        if notes
        else '<p class="note">none</p>',
    )


def add_bundle_fit(
    report: Report,
    fit,
    title: str | None = None,
    *,
    unit: str = "m",
    angle_unit: str = "deg",
    max_rows: int = MAX_ROWS,
) -> dict:
    """Add the sections of a :class:`~photogeom.bundle.BundleFit` to ``report``.

    Parameters
    ----------
    report : Report
        The report to add to.
    fit : BundleFit
        The adjustment.
    title : str, optional
        Chapter heading.
    unit : str, default "m"
        Length unit of the object coordinates (labels).
    angle_unit : str, default "deg"
        Unit of the angles shown.
    max_rows : int, default MAX_ROWS
        Rows of the long tables at most.

    Returns
    -------
    dict
        The result record (see :func:`bundle_result_data`) the sections were rendered from.
    """
    data = bundle_result_data(fit, unit=unit, angle_unit=angle_unit)
    add_bundle_result(report, data, title, max_rows=max_rows)
    return data


def bundle_report(
    fit_or_data,
    title: str = "Bundle adjustment",
    *,
    unit: str = "m",
    angle_unit: str = "deg",
    max_rows: int = MAX_ROWS,
) -> Report:
    """A complete HTML report of a bundle adjustment (a ``BundleFit`` or a result record).

    >>> bundle_report(fit).write("bundle.html")                      # doctest: +SKIP

    Parameters
    ----------
    fit_or_data : BundleFit or Mapping
        The adjustment, or its result record (:func:`read_bundle_result`).
    title : str, default "Bundle adjustment"
        Title of the report.
    unit : str, default "m"
        Length unit of the object coordinates (for a ``BundleFit``).
    angle_unit : str, default "deg"
        Unit of the angles shown (for a ``BundleFit``).
    max_rows : int, default MAX_ROWS
        Rows of the long tables at most.

    Returns
    -------
    Report
    """
    if isinstance(fit_or_data, Mapping):
        data = fit_or_data
    else:
        data = bundle_result_data(fit_or_data, unit=unit, angle_unit=angle_unit)
    blk = data["block"]
    rep = Report(
        title,
        subtitle=f"{blk['n_images']} images, {blk['n_points']} points, "
        f"{blk['n_image_observations']} image observations; residuals are computed "
        "minus observed, in pixels",
    )
    add_bundle_result(rep, data, max_rows=max_rows)
    return rep
