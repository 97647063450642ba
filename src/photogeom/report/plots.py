"""Residual vector plots (matplotlib, drawn off-screen: no display needed)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from ..errors import InputError

#: Points whose ids :func:`residual_figure` writes beside them at most (all groups together);
#: with more, no id is drawn and the figure says so.
MAX_ID_LABELS = 200

#: Arrows :func:`residual_figure` draws at most (all groups together); with more points, the
#: :data:`LONGEST_ALWAYS_SHOWN` longest and an even random sample of the others are drawn and
#: the figure says "N of M shown".
MAX_ARROWS = 3000

#: Arrows always drawn when the points are thinned: this many of the longest.
LONGEST_ALWAYS_SHOWN = 600

#: Residuals longer than this multiple of the 90th percentile of the lengths are drawn clipped
#: to it, in :data:`CLIPPED_COLOUR`. For normal noise (Rayleigh lengths) a residual 3 times
#: the 90th percentile has a probability of about 1e-9: only blunders are clipped.
CLIP_RATIO = 3.0

#: Colour of the clipped arrows.
CLIPPED_COLOUR = "#e69f00"


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


@dataclass(frozen=True)
class ArrowScale:
    """How :func:`residual_figure` draws residual arrows (see :func:`arrow_scale`).

    Attributes
    ----------
    factor : float
        Exaggeration: a residual of length 1 (residual unit) is drawn ``factor`` position
        units long.
    key : float
        True length of the scale arrow (residual unit), drawn ``key * factor`` long; 0 when
        every residual is zero.
    typical : float
        90th percentile of the residual lengths (residual unit) the scale follows.
    clip : float
        Residuals longer than this (residual unit) are drawn this long, in
        :data:`CLIPPED_COLOUR`; ``inf`` when none is.
    clipped : numpy.ndarray of bool, shape (n,)
        Rows longer than ``clip``.
    shown : numpy.ndarray of bool, shape (n,)
        Rows drawn (finite, and chosen when there are more than ``max_arrows``).
    """

    factor: float
    key: float
    typical: float
    clip: float
    clipped: np.ndarray
    shown: np.ndarray

    def drawn(self, residuals_xy) -> np.ndarray:
        """The residuals as drawn (residual unit): the clipped rows shortened to
        :attr:`clip` in their direction, the others as they are."""
        r = np.asarray(residuals_xy, dtype=float)
        length = np.hypot(r[:, 0], r[:, 1])
        shrink = np.ones(length.size)
        shrink[self.clipped] = self.clip / length[self.clipped]
        return r * shrink[:, None]

    def quiver(self, ax, positions, drawn, rows, **style):
        """Draw arrows at this scale on ``ax``: ``drawn`` (residual unit, as from
        :meth:`drawn`) at ``positions`` (position unit), the ``rows`` selected; ``style``
        goes to matplotlib's ``quiver`` (colour, width, label, zorder). Returns the quiver
        (for a scale arrow)."""
        return ax.quiver(
            positions[rows, 0],
            positions[rows, 1],
            drawn[rows, 0],
            drawn[rows, 1],
            angles="xy",
            scale_units="xy",
            scale=1.0 / self.factor,
            **style,
        )

    def applied_to(self, residuals_xy, max_arrows: int = MAX_ARROWS) -> ArrowScale:
        """The same exaggeration, scale arrow and clipping length for other residuals:
        those given as ``drawn_too`` to :func:`arrow_scale` (a second panel at the same
        scale, rows that do not set it), with their own clipped and shown rows.

        Parameters
        ----------
        residuals_xy : array_like, shape (m, 2)
            Residual vectors, in the unit of the ones the scale was made for.
        max_arrows : int, default :data:`MAX_ARROWS`
            Arrows drawn at most (thinned as in :func:`arrow_scale`).

        Returns
        -------
        ArrowScale
            :attr:`factor`, :attr:`key`, :attr:`typical` and :attr:`clip` of this one.
        """
        r = np.asarray(residuals_xy, dtype=float)[:, :2]
        length = np.hypot(r[:, 0], r[:, 1])
        finite = np.isfinite(length)
        clipped = finite & (length > self.clip)
        shown = _thinned(length, finite, max_arrows)
        return ArrowScale(self.factor, self.key, self.typical, self.clip, clipped, shown)


def _thinned(length: np.ndarray, finite: np.ndarray, max_arrows: int) -> np.ndarray:
    """Rows drawn: every finite one, or with more than ``max_arrows`` the
    :data:`LONGEST_ALWAYS_SHOWN` longest and a seeded random sample of the others."""
    idx = np.flatnonzero(finite)
    if idx.size <= max_arrows:
        return finite.copy()
    order = idx[np.argsort(-length[idx], kind="stable")]
    big = min(LONGEST_ALWAYS_SHOWN, max_arrows)
    rest = np.random.default_rng(0).choice(order[big:], max_arrows - big, replace=False)
    shown = np.zeros(length.size, dtype=bool)
    shown[order[:big]] = True
    shown[rest] = True
    return shown


def arrow_scale(
    residuals_xy, extent: float, max_arrows: int = MAX_ARROWS, *, drawn_too=None
) -> ArrowScale:
    """Exaggeration, scale arrow, clipping and thinning of residual arrows.

    The scale follows the 90th percentile of the lengths (not the longest: a few blunders
    would shrink every other arrow to a dot): it is drawn 15 % of ``extent`` long, but no
    drawn arrow is longer than 30 % of it. Residuals longer than :data:`CLIP_RATIO` times
    the 90th percentile are drawn clipped to that length. With more than ``max_arrows``
    finite rows, the :data:`LONGEST_ALWAYS_SHOWN` longest and a random sample of the others
    (fixed seed: the same figure every run) are shown.

    Parameters
    ----------
    residuals_xy : array_like, shape (n, 2)
        Residual vectors, any unit.
    extent : float
        Size of the plotted area (position unit, > 0).
    max_arrows : int, default :data:`MAX_ARROWS`
        Arrows drawn at most.
    drawn_too : array_like, shape (m, 2), optional
        Residuals drawn at the same scale that do not set it (another panel, cells of few
        observations): the 90th percentile is that of ``residuals_xy`` alone, the clipping
        and the longest drawn arrow count these too. Draw them with
        :meth:`ArrowScale.applied_to`.

    Returns
    -------
    ArrowScale
    """
    r = np.asarray(residuals_xy, dtype=float)[:, :2]
    length = np.hypot(r[:, 0], r[:, 1])
    finite = np.isfinite(length)
    n = length.size
    none = np.zeros(n, dtype=bool)
    if not finite.any() or not (length[finite] > 0).any():
        return ArrowScale(1.0, 0.0, 0.0, math.inf, none, finite)
    good = length[finite]
    vmax = float(good.max())
    if drawn_too is not None:
        t = np.asarray(drawn_too, dtype=float).reshape(-1, 2)
        extra = np.hypot(t[:, 0], t[:, 1])
        extra = extra[np.isfinite(extra)]
        if extra.size:
            vmax = max(vmax, float(extra.max()))
    typical = float(np.quantile(good, 0.9))
    if typical <= 0:  # nearly all zero: the few others set the scale
        typical = float(np.quantile(good[good > 0], 0.9))
    clip = CLIP_RATIO * typical if vmax > CLIP_RATIO * typical else math.inf
    longest = min(vmax, clip)
    factor = nice_length(min(0.15 * extent / typical, 0.3 * extent / longest))
    key = nice_length(typical)
    clipped = finite & (length > clip)
    return ArrowScale(factor, key, typical, clip, clipped, _thinned(length, finite, max_arrows))


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
    draw_r = np.where(finite[:, None], all_r, np.nan)
    sc = arrow_scale(draw_r, extent)
    factor, key = sc.factor, sc.key
    vmax = float(np.hypot(draw_r[finite, 0], draw_r[finite, 1]).max()) if finite.any() else 0.0
    drawn_r = sc.drawn(draw_r)  # clipped arrows: CLIP_RATIO x typical long, in their direction
    starts = np.cumsum([0] + [g[0].shape[0] for g in groups])

    fig = Figure(figsize=(6.4, 5.6), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    handles = []
    shown_by_number = []
    n_points = sum(g[0].shape[0] for g in groups)
    n_shown = int(sc.shown.sum())
    thinned = n_shown < int(finite.sum())
    # more ids than a figure can show legibly: none drawn (drawing thousands of labels took
    # most of a report's time, 40 s for 5000 points, and covered the arrows)
    label = n_points <= MAX_ID_LABELS
    for k, (p, _r, pid, group, colour) in enumerate(groups):
        rows = slice(starts[k], starts[k + 1])
        show = sc.shown[rows]
        plain_rows = show & ~sc.clipped[rows]
        d = drawn_r[rows]
        ax.plot(p[show, 0], p[show, 1], "o", color=colour, ms=4 if not thinned else 2, zorder=3)
        count = f"{int(show.sum())} of {p.shape[0]} shown" if thinned else f"{p.shape[0]}"
        q = sc.quiver(
            ax,
            p,
            d,
            plain_rows,
            color=colour,
            width=0.005 if not thinned else 0.003,
            zorder=4,
            label=plain(f"{group} ({count})"),
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
    n_clipped = int(sc.clipped.sum())
    clip_text = f"{sc.clip:.3g} {unit}".strip()
    if n_clipped:
        sel = sc.clipped & sc.shown
        sc.quiver(
            ax,
            all_p,
            drawn_r,
            sel,
            color=CLIPPED_COLOUR,
            width=0.005 if not thinned else 0.003,
            zorder=5,
            label=plain(f"longer than {clip_text}, clipped ({n_clipped})"),
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
    pad = 0.12 * extent + (min(vmax, sc.clip) * factor if vmax > 0 else 0)
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
    if n_clipped:
        note += (
            f"\n{n_clipped} arrow(s) longer than {clip_text} drawn clipped to it"
            f" ({CLIP_RATIO:g} x the 90th percentile), in orange"
        )
    if thinned:
        note += (
            f"\narrows: {n_shown} of {int(finite.sum())} shown"
            f" (the {min(LONGEST_ALWAYS_SHOWN, n_shown)} longest and a random sample)"
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
