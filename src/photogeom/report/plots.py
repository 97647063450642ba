"""Residual vector plots (matplotlib, drawn off-screen: no display needed)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from ..errors import InputError

#: Points whose ids :func:`residual_figure` writes beside them at most (all groups together);
#: with more, no id is drawn and the figure says so.
MAX_ID_LABELS = 200


def nice_length(value: float) -> float:
    """The largest 1, 2 or 5 times a power of ten not above ``value``.

    Parameters
    ----------
    value : float
        A length, any unit.

    Returns
    -------
    float
        In the unit of ``value``; 1.0 for a value that is not positive and finite.
    """
    if not (value > 0 and math.isfinite(value)):
        return 1.0
    exp = math.floor(math.log10(value))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0**exp <= value * (1 + 1e-12):
            return m * 10.0**exp
    return 10.0**exp  # pragma: no cover


def plain(text) -> str:
    """``text`` (an id, a label, a file or camera name, a unit) as matplotlib draws it
    literally.

    matplotlib reads text between two ``$`` as mathtext: ``$a^$`` fails to parse (the whole
    figure fails with it) and ``$b$`` is drawn as math. Every ``$`` is escaped (``\\$``), which
    any text artist (titles, annotations, tick labels, legend entries, quiver keys) then
    draws as a plain ``$``. Use it on every text that comes from the data or the user.

    Parameters
    ----------
    text : object
        Converted with ``str``.

    Returns
    -------
    str
        The text with ``$`` escaped.
    """
    return str(text).replace("$", "\\$")


def _xy(a, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise InputError(f"{name}: expected shape (n, 2), got {arr.shape}")
    return arr[:, :2]


def residual_figure(
    points_xy,
    residuals_xy,
    ids: Sequence | None = None,
    *,
    unit: str = "",
    labels: tuple[str, str] = ("x", "y"),
    check_points=None,
    check_residuals=None,
    check_ids: Sequence | None = None,
    y_down: bool = False,
    title: str | None = None,
    point_unit: str | None = None,
    name: str = "control",
) -> Figure:
    """Quiver plot of residual vectors at their points, with a labelled scale arrow.

    Parameters
    ----------
    points_xy : array_like, shape (n, 2)
        Positions (e.g. image or plan coordinates) of the residual rows.
    residuals_xy : array_like, shape (n, 2)
        Residuals (computed minus observed) at those positions, unit ``unit``.
    ids : sequence, optional
        Point ids written next to the points (with at most :data:`MAX_ID_LABELS` points in
        all; with more, none is written and the figure says so).
    unit : str
        Residual unit, shown on the scale arrow.
    labels : (str, str)
        Axis names of the positions.
    check_points, check_residuals, check_ids : optional
        Check points, drawn in another colour.
    y_down : bool
        Draw the second axis downwards (pixel systems: row grows down).
    title : str, optional
        Line above the plot, before the note on the arrows' exaggeration.
    point_unit : str, optional
        Unit of the positions (axis labels); defaults to ``unit``.
    name : str, default "control"
        What the points are, in the legend (``"control (12)"``); e.g. ``"object points"``
        for the rays of an intersection, which are neither control nor check points.

    Returns
    -------
    matplotlib.figure.Figure
        The arrows are exaggerated by a common factor (stated in the figure); the scale
        arrow gives their true length.
    """
    pts = _xy(points_xy, "points")
    res = _xy(residuals_xy, "residuals")
    if pts.shape[0] != res.shape[0]:
        raise InputError(f"{pts.shape[0]} point(s) but {res.shape[0]} residual row(s)")
    groups = [(pts, res, ids, name, "#1f5fa8")]
    if check_points is not None and check_residuals is not None:
        cp, cr = _xy(check_points, "check points"), _xy(check_residuals, "check residuals")
        if cp.shape[0] != cr.shape[0]:
            raise InputError(f"{cp.shape[0]} check point(s) but {cr.shape[0]} residual row(s)")
        if cp.shape[0]:
            groups.append((cp, cr, check_ids, "check", "#c0392b"))
    all_p = np.vstack([g[0] for g in groups])
    all_r = np.vstack([g[1] for g in groups])
    finite = np.isfinite(all_p).all(axis=1) & np.isfinite(all_r).all(axis=1)
    extent = float(np.ptp(all_p[finite], axis=0).max()) if finite.any() else 1.0
    if extent <= 0:
        extent = 1.0
    vmax = float(np.sqrt((all_r[finite] ** 2).sum(axis=1)).max()) if finite.any() else 0.0
    factor = nice_length(0.15 * extent / vmax) if vmax > 0 else 1.0
    key = nice_length(vmax) if vmax > 0 else 0.0

    fig = Figure(figsize=(6.4, 5.6), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    handles = []
    shown_by_number = []
    n_points = sum(g[0].shape[0] for g in groups)
    # more ids than a figure can show legibly: none drawn (drawing thousands of labels took
    # most of a report's time, 40 s for 5000 points, and covered the arrows)
    label = n_points <= MAX_ID_LABELS
    for p, r, pid, group, colour in groups:
        ax.plot(p[:, 0], p[:, 1], "o", color=colour, ms=4, zorder=3)
        q = ax.quiver(
            p[:, 0],
            p[:, 1],
            r[:, 0],
            r[:, 1],
            angles="xy",
            scale_units="xy",
            scale=1.0 / factor,
            color=colour,
            width=0.005,
            zorder=4,
            label=plain(f"{group} ({p.shape[0]})"),
        )
        handles.append(q)
        if pid is not None and label:
            texts, font, missing = point_labels([str(t) for t in pid], group)
            shown_by_number += missing
            for (x, y), t in zip(p, texts):
                ax.annotate(
                    plain(t),
                    (x, y),
                    textcoords="offset points",
                    xytext=(5, 5),
                    fontsize=8,
                    color=colour,
                    fontproperties=font,
                )
    if key > 0:
        # the scale arrow in the lower-left corner inside the axes (kept free by the padding
        # below), away from the title above and the legend in the lower right
        ax.quiverkey(
            handles[0],
            X=0.1,
            Y=0.05,
            U=key,
            label=plain(f"{key:g} {unit}".strip()),
            labelpos="E",
            coordinates="axes",
            color="black",
            fontproperties={"size": 8.5},
        )
    pad = 0.12 * extent + (0.15 * extent if vmax > 0 else 0)
    lo = all_p[finite].min(axis=0) if finite.any() else np.zeros(2)
    hi = all_p[finite].max(axis=0) if finite.any() else np.ones(2)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    if y_down:
        ax.set_ylim(hi[1] + pad, lo[1] - pad)
    else:
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    pu = unit if point_unit is None else point_unit
    ax.set_xlabel(plain(f"{labels[0]} [{pu}]" if pu else labels[0]))
    ax.set_ylabel(plain(f"{labels[1]} [{pu}]" if pu else labels[1]))
    ax.grid(True, color="#dddddd", lw=0.6)
    ax.legend(loc="lower right", fontsize=8, framealpha=0.8)
    exaggeration = f"{factor:,.0f}" if factor >= 10 else f"{factor:.3g}"
    note = (
        f"v = computed - observed, arrows x{exaggeration}" if vmax > 0 else "all residuals are zero"
    )
    if not label and any(g[2] is not None for g in groups):
        note += f"\nids not drawn ({n_points} points, more than {MAX_ID_LABELS})"
    if shown_by_number:
        # the ids themselves cannot be drawn: refer to the rows of the residual tables
        note += (
            f"\n{len(shown_by_number)} id(s) the font cannot draw: #k = row k of the residual table"
        )
    ax.set_title(plain((title + "\n" if title else "") + note), fontsize=9.5, loc="left")
    fig.tight_layout()
    return fig


def point_labels(ids: Sequence[str], group: str = "") -> tuple[list[str], object, list[str]]:
    """Labels for point ids, in a font that can draw them.

    Returns the labels, the font properties to draw them with (None: matplotlib's default
    font) and ``"label = id"`` entries for ids no installed font can draw, which are labelled
    ``#k`` (k = their position, 1-based) instead of showing empty boxes.
    """
    from matplotlib.font_manager import FontProperties

    needed = {ch for t in ids for ch in t if not ch.isspace()}
    default = _charmap(None)
    if needed <= default[1]:
        return list(ids), None, []
    font = _font_covering(needed)
    if font is not None:
        return list(ids), FontProperties(fname=font), []
    prefix = "c" if group == "check" else ""
    out, missing = [], []
    for k, t in enumerate(ids, start=1):
        if set(t.replace(" ", "")) <= default[1]:
            out.append(t)
        else:
            label = f"#{prefix}{k}"
            out.append(label)
            missing.append(f"{label} = {t}")
    return out, None, missing


_CHARMAPS: dict = {}


def _charmap(path: str | None) -> tuple[str, frozenset]:
    """(font file, code points it draws) of ``path`` or of matplotlib's default font."""
    if path not in _CHARMAPS:
        from matplotlib import font_manager
        from matplotlib.ft2font import FT2Font

        file = path or font_manager.findfont(font_manager.FontProperties())
        try:
            chars = frozenset(chr(c) for c in FT2Font(file).get_charmap())
        except (OSError, RuntimeError, ValueError):
            chars = frozenset()
        _CHARMAPS[path] = (file, chars)
    return _CHARMAPS[path]


def _font_covering(chars: set) -> str | None:
    """An installed font file that draws every character of ``chars``, or None."""
    from matplotlib import font_manager

    names = ("cjk", "noto", "droid", "wenquanyi", "unifont", "ipa", "takao", "arphic", "symbola")
    candidates = sorted(
        {f.fname for f in font_manager.fontManager.ttflist},
        key=lambda f: (not any(n in f.lower() for n in names), f),
    )
    for file in candidates[:60]:
        if "lastresort" in file.lower():  # maps every character to a box
            continue
        if chars <= _charmap(file)[1]:
            return file
    return None
