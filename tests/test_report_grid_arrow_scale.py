"""The residual-grid figures of ``grid fit --report`` (mean node vectors) and ``grid report``
(mean residual vectors over the sensor before and after, the study's Figures 7 and 9) keep
the ordinary arrows visible when one vector is far longer than the others: the scale follows
the 90th percentile of the lengths, the long ones are clipped in their own colour and
counted, and the scale arrow is drawn as long as its label says."""

from __future__ import annotations

import dataclasses

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.quiver import Quiver, QuiverKey

from photogeom.report.plots import CLIPPED_COLOUR


def _quivers(ax):
    return [c for c in ax.collections if isinstance(c, Quiver)]


def _drawn(q):
    """Drawn arrow lengths in data units (angles='xy', scale_units='xy')."""
    return np.hypot(q.U, q.V) / q.scale


def test_mean_grid_with_one_long_node_vector_keeps_the_others_visible(monkeypatch):
    """A 40 px node vector (an edge node of little support) among node vectors of about
    0.5 px: the mean grid was scaled to it, the median arrow drawn 0.5 % of a node spacing
    long; now 20 %, the long one clipped in orange and counted."""
    from photogeom.calibration import fit_grids
    from photogeom.cli import grid as grid_cli
    from photogeom.report import html as report_html

    w, h, spacing = 600, 400, 50.0
    rng = np.random.default_rng(4)
    uv = np.column_stack([rng.uniform(0, w - 1, 1500), rng.uniform(0, h - 1, 1500)])
    r = np.column_stack([np.sin(uv[:, 0] / 150), np.cos(uv[:, 1] / 120)]) * 0.5
    (grid,) = fit_grids({"a": (uv, r)}, (w, h), spacing, folds=0).values()
    nodes = grid.nodes.copy()
    nodes[0, -1] = [40.0, -30.0]  # 50 px at the top-right corner node
    grids = {"a": dataclasses.replace(grid, nodes=nodes)}
    figures = []
    real = report_html.figure_to_png

    def keep(fig, dpi=110):
        figures.append(fig)
        return real(fig, dpi)

    monkeypatch.setattr(report_html, "figure_to_png", keep)
    grid_cli._report_html(grids)
    (fig,) = figures
    (ax,) = fig.axes
    qs = _quivers(ax)
    assert np.median(_drawn(qs[0])) / spacing > 0.1
    ordinary, clipped = qs
    lengths = np.hypot(nodes[..., 0], nodes[..., 1]).ravel()
    assert ordinary.N == lengths.size - 1 and clipped.N == 1
    assert _drawn(clipped).max() <= 1.2 * spacing * (1 + 1e-9)
    assert np.allclose(clipped.get_facecolor()[0], to_rgba(CLIPPED_COLOUR))
    clip = 3 * np.quantile(lengths, 0.9)
    assert np.hypot(clipped.U, clipped.V)[0] == pytest.approx(clip)
    assert f"1 longer than {clip:.3g} px clipped" in ax.get_title(loc="left")
    (key,) = [a for a in ax.artists if isinstance(a, QuiverKey)]
    assert key.text.get_text() == f"{key.U:g} px"
    assert key.Q is ordinary
    assert 0.5 * np.quantile(lengths, 0.9) <= key.U <= np.quantile(lengths, 0.9)


class _Sensor:
    """What the sensor figure asks of a block: its image size."""

    def __init__(self, means):
        self.means = means

    def image_sizes(self):
        return np.array([[4000, 3000]])


def test_sensor_figures_with_one_long_cell_mean_keep_the_others_visible(monkeypatch):
    """Mean residual vectors of 12 x 8 sensor cells, about 1.5 px before and 0.5 px after,
    one cell of few observations at 25 px: both panels were scaled to it, the median arrow
    before drawn 0.63 % of the sensor width; now 2.5 %, at the same scale in both panels,
    the long one clipped in orange and counted."""
    from photogeom.report import grid_study

    rng = np.random.default_rng(8)
    gx, gy = np.meshgrid((np.arange(12) + 0.5) * 4000 / 12, (np.arange(8) + 0.5) * 3000 / 8)
    centres = np.column_stack([gx.ravel(), gy.ravel()])
    before = rng.normal(0, 1.5, (96, 2))
    before[11] = [25.0, 3.0]
    after = rng.normal(0, 0.5, (96, 2))
    monkeypatch.setattr(
        grid_study,
        "sensor_mean_residuals",
        lambda block: (centres, block.means, np.full(96, 50)),
    )
    fig = grid_study._fig_sensor(_Sensor(before), _Sensor(after))
    ax_before, ax_after = fig.axes
    qs = _quivers(ax_before)
    assert np.median(_drawn(qs[0])) / 4000 > 0.015
    (ordinary, clipped, key_before) = qs
    assert ordinary.N == 95 and clipped.N == 1
    assert np.allclose(clipped.get_facecolor()[0], to_rgba(CLIPPED_COLOUR))
    lengths = np.hypot(before[:, 0], before[:, 1])
    clip = 3 * np.quantile(lengths, 0.9)
    assert "1 longer than" in ax_before.get_title() and f"{clip:.3g} px" in ax_before.get_title()
    # the same exaggeration in both panels: drawn over true length
    k_before = np.median(_drawn(ordinary) / np.delete(lengths, 11))
    (after_arrows, key_after) = _quivers(ax_after)
    k_after = np.median(_drawn(after_arrows) / np.hypot(after[:, 0], after[:, 1]))
    assert k_after == pytest.approx(k_before)
    # the scale arrow: drawn with the arrows' exaggeration, labelled with its true length
    for ax, key in ((ax_before, key_before), (ax_after, key_after)):
        (label,) = [t.get_text() for t in ax.texts if t.get_text().endswith(" px")]
        assert _drawn(key)[0] / k_before == pytest.approx(float(label.split()[0]))
    assert 0.5 * np.quantile(lengths, 0.9) <= float(label.split()[0]) <= np.quantile(lengths, 0.9)


@pytest.mark.parametrize("strong_outlier", [True, False])
def test_bundle_sensor_grid_with_a_long_cell_mean_keeps_the_others_visible(strong_outlier):
    """The bundle report's residuals over the sensor, cell means of 0.3 px: one
    well-observed cell of 20 px shrank the others to 3 % of a cell (the scale was bounded by
    the longest well-observed cell), and a cell of 2 observations with a 30 px mean, left out
    of the scale, was drawn 30 cells long across the figure (3 with the 20 px cell). Now the
    typical arrow is drawn 0.3-1.2 cells long, the long means clipped in orange and counted,
    no arrow over 3 cells."""
    from photogeom.report.bundle import sensor_grid_figure

    rng = np.random.default_rng(2)
    nx, ny, w, h = 10, 8, 5000, 4000
    mean = rng.normal(0, 0.3, (nx * ny, 2))
    count = np.full(nx * ny, 40)
    if strong_outlier:
        mean[12] = [20.0, 0.0]
    mean[0], count[0] = [0.0, 30.0], 2
    grid = {
        "label": "camera A",
        "width": w,
        "height": h,
        "nx": nx,
        "ny": ny,
        "mean": mean.tolist(),
        "count": count.tolist(),
        "n_observations": int(count.sum()),
        "n_images": 6,
        "rms": 0.5,
    }
    fig = sensor_grid_figure([grid])
    (ax,) = fig.axes
    cell = w / nx
    qs = _quivers(ax)
    assert np.median(_drawn(qs[0])) / cell > 0.25
    assert max(_drawn(q).max() for q in qs) <= 3 * cell
    n_long = 2 if strong_outlier else 1
    strong = qs[0]
    assert strong.N == nx * ny - n_long
    (clipped,) = [q for q in qs if np.allclose(q.get_facecolor()[0], to_rgba(CLIPPED_COLOUR))]
    assert clipped.N == n_long
    lengths = np.hypot(mean[:, 0], mean[:, 1])
    clip = 3 * np.quantile(np.delete(lengths, 0), 0.9)  # the well-observed cells
    assert f"{n_long} longer than {clip:.3g} px clipped" in ax.get_title(loc="left")
    (key,) = [a for a in ax.artists if isinstance(a, QuiverKey)]
    assert key.text.get_text() == f"{key.U:g} px"
    assert key.Q.scale == pytest.approx(strong.scale)


def test_sensor_after_panel_clips_a_long_mean_the_before_panel_lacks(monkeypatch):
    """The after panel is drawn at the before panel's scale: a 40 px cell mean after the
    correction, longer than every mean before, was drawn unclipped, half the sensor width
    long. It is clipped to 3 times the typical length before, in orange, and counted."""
    from photogeom.report import grid_study

    rng = np.random.default_rng(9)
    gx, gy = np.meshgrid((np.arange(12) + 0.5) * 4000 / 12, (np.arange(8) + 0.5) * 3000 / 8)
    centres = np.column_stack([gx.ravel(), gy.ravel()])
    before = rng.normal(0, 1.5, (96, 2))
    after = rng.normal(0, 0.5, (96, 2))
    after[40] = [0.0, -40.0]
    monkeypatch.setattr(
        grid_study,
        "sensor_mean_residuals",
        lambda block: (centres, block.means, np.full(96, 50)),
    )
    fig = grid_study._fig_sensor(_Sensor(before), _Sensor(after))
    _, ax_after = fig.axes
    qs = _quivers(ax_after)
    assert max(_drawn(q).max() for q in qs) < 0.3 * 4000
    (clipped,) = [q for q in qs if np.allclose(q.get_facecolor()[0], to_rgba(CLIPPED_COLOUR))]
    assert clipped.N == 1
    assert "1 longer than" in ax_after.get_title()
