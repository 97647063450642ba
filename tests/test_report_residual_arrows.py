"""Residual vector figures stay readable with blunders and with many points: the scale
follows the typical residual, blunders are drawn clipped and counted, the scale arrow is as
long as its label says, and very many points are thinned (the longest always drawn)."""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.report.plots import (
    CLIPPED_COLOUR,
    LONGEST_ALWAYS_SHOWN,
    MAX_ARROWS,
    arrow_scale,
    residual_figure,
)

matplotlib = pytest.importorskip("matplotlib")

from matplotlib.colors import to_rgba  # noqa: E402
from matplotlib.quiver import Quiver, QuiverKey  # noqa: E402


def _block(n, seed=5, blunders=3):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 1000, (n, 2))
    res = rng.normal(0, 0.3, (n, 2))
    res[:blunders] = [[8.0, 0.0], [0.0, -8.0], [5.7, 5.7]][:blunders]
    return pts, res


def _quivers(ax):
    return [c for c in ax.collections if isinstance(c, Quiver)]


def _drawn_lengths(q):
    """Drawn arrow lengths in data units (angles='xy', scale_units='xy')."""
    return np.hypot(q.U, q.V) / q.scale


def test_blunders_do_not_shrink_the_ordinary_arrows():
    pts, res = _block(400)
    fig = residual_figure(pts, res, unit="px", labels=("u", "v"), y_down=True)
    (ax,) = fig.axes
    width = abs(np.diff(ax.get_xlim())[0])
    qs = _quivers(ax)
    ordinary = [q for q in qs if q.get_label().startswith("control")]
    clipped = [q for q in qs if "clipped" in q.get_label()]
    assert len(ordinary) == 1 and len(clipped) == 1
    # the 397 ordinary arrows: a median 2.1 % of the axes width (before: 0.23 %)
    lengths = _drawn_lengths(ordinary[0])
    assert lengths.size == 397
    assert np.median(lengths) / width > 0.015
    # the three 8 px blunders: drawn clipped to 3 x the 90th percentile, in their own colour,
    # counted in the legend and the title
    (q,) = clipped
    assert q.N == 3
    assert np.allclose(q.get_facecolor()[0], to_rgba(CLIPPED_COLOUR))
    lengths_true = np.hypot(res[:, 0], res[:, 1])
    clip = 3 * np.quantile(lengths_true, 0.9)
    assert np.allclose(np.hypot(q.U, q.V), clip)
    assert f"longer than {clip:.3g} px, clipped (3)" in q.get_label()
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "control (400)" in legend and any("clipped (3)" in t for t in legend)
    assert "3 arrow(s) longer than" in ax.get_title(loc="left")
    # no drawn arrow runs far outside the plotted area
    assert max(_drawn_lengths(q).max(), lengths.max()) < 0.35 * width
    # the scale arrow: its label is its true length, drawn with the arrows' exaggeration
    (key,) = [a for a in ax.artists if isinstance(a, QuiverKey)]
    assert key.text.get_text() == f"{key.U:g} px"
    assert key.Q.scale == pytest.approx(ordinary[0].scale) == pytest.approx(q.scale)
    assert 0.5 * np.quantile(lengths_true, 0.9) <= key.U <= np.quantile(lengths_true, 0.9)
    factor = 1 / q.scale
    assert f"arrows x{factor:,.0f}" in ax.get_title(loc="left")


def test_without_blunders_nothing_is_clipped():
    rng = np.random.default_rng(2)
    pts = rng.uniform(0, 100, (2000, 2))
    res = rng.normal(0, 0.01, (2000, 2))
    fig = residual_figure(pts, res, unit="m")
    (ax,) = fig.axes
    assert not any("clipped" in q.get_label() for q in _quivers(ax))
    assert "clipped" not in ax.get_title(loc="left")
    (q,) = _quivers(ax)
    assert q.N == 2000


def test_many_points_are_thinned_longest_always_drawn():
    pts, res = _block(50_000, seed=7, blunders=3)
    res[3:40] *= 1.5  # large but not clipped: among the longest, always drawn
    fig = residual_figure(pts, res, unit="px")
    (ax,) = fig.axes
    qs = _quivers(ax)
    assert sum(q.N for q in qs) == MAX_ARROWS
    (ordinary,) = [q for q in qs if q.get_label().startswith("control")]
    assert f"control ({MAX_ARROWS} of 50000 shown)" == ordinary.get_label()
    assert f"arrows: {MAX_ARROWS} of 50000 shown" in ax.get_title(loc="left")
    # the longest LONGEST_ALWAYS_SHOWN residuals are all among the drawn ones
    sc = arrow_scale(res, 1000.0)
    longest = np.argsort(-np.hypot(res[:, 0], res[:, 1]))[:LONGEST_ALWAYS_SHOWN]
    assert sc.shown[longest].all() and sc.shown.sum() == MAX_ARROWS
    assert sc.clipped[:3].all() and sc.clipped.sum() == 3
    # drawn positions are the chosen rows (markers too: no solid blob of 50 000 dots)
    (clipped,) = [q for q in qs if "clipped" in q.get_label()]
    assert clipped.N == 3
    markers = [ln for ln in ax.lines if ln.get_marker() == "o"]
    assert sum(ln.get_xdata().size for ln in markers) == MAX_ARROWS
    # the same figure every run
    assert np.array_equal(arrow_scale(res, 1000.0).shown, sc.shown)
