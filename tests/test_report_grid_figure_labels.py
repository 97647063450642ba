"""Figures 8 and 10 of 'grid report' say what they are, in the words and units of the
others.

Before: the image figure (the study's Figure 8) was the only one without its figure
number, and its grid panel said "every 2. node"; the step-against-grid-size figure (Figure
10) labelled its log axis "10^2", "2 x 10^2", ..., not the spacings tried.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom.calibration import GridLayout
from photogeom.report import grid_study
from photogeom.report.grid_study import _fig_image, _fig_sweep

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes


@pytest.mark.parametrize(("spacing", "every"), [(100, "every 2nd node"), (500, "every node")])
def test_the_image_figure_is_figure_8(monkeypatch, spacing, every):
    rng = np.random.default_rng(0)
    uv = rng.uniform([0, 0], [3999, 2999], (50, 2))
    monkeypatch.setattr(grid_study, "block_residuals", lambda block: {"a": (uv, 0.1 * uv / 4000)})
    layout = GridLayout(4000, 3000, spacing)
    grids = {"a": grid_with_nodes(layout, np.full((*layout.shape, 2), 0.2))}
    left, right = _fig_image(None, grids, "a").axes
    assert left.get_title() == "image a: tie-point residuals, exaggerated (Fig. 8)"
    assert right.get_title() == f"fitted grid, {spacing} px, {every} (Fig. 8)"


def test_every_nth():
    got = [grid_study._every(k) for k in (1, 2, 3, 4, 11, 12, 13, 21, 22, 23, 111)]
    assert got == [
        "every node", "every 2nd node", "every 3rd node", "every 4th node",
        "every 11th node", "every 12th node", "every 13th node", "every 21st node",
        "every 22nd node", "every 23rd node", "every 111th node",
    ]  # fmt: skip


def test_the_sweep_axis_is_labelled_with_the_spacings():
    spacings = [100.0, 150.0, 200.0, 300.0, 500.0, 1000.0, 2000.0]
    n = len(spacings)
    sweep = {
        "spacings": spacings,
        "step": [np.linspace(1.0, 1.4, n)] * 2,
        "step_before": [1.5, 1.5],
        "choice": {
            "step_norm": np.tile(np.linspace(0, 1, n), (2, 1)),
            "time_norm": np.tile(np.linspace(1, 0, n), (2, 1)),
            "index": [2, 2],
        },
        "spacing": 200.0,
    }
    fig = _fig_sweep(sweep)
    ax = fig.axes[0]
    fig.canvas.draw()
    major = [t.get_text() for t in ax.get_xticklabels()]
    minor = [t.get_text() for t in ax.get_xticklabels(minor=True) if t.get_text()]
    assert major == ["100", "150", "200", "300", "500", "1000", "2000"]
    assert minor == []
    assert ax.get_xlabel() == "grid spacing (px)"
    assert ax.get_title() == "step against grid size (Fig. 10)"


def test_each_spacing_is_labelled_at_its_point_closest_to_the_origin():
    """Figure 13 put each spacing's label at the mean of the models' points: for 300 px,
    models at (time, step) = (0.4, 0.1) and (0.4, 0.9), at (0.4, 0.5), away from both."""
    spacings = [100.0, 300.0, 1000.0]
    tn = np.array([[1.0, 0.4, 0.0], [1.0, 0.4, 0.0], [1.0, 0.4, 0.0]])  # one time per spacing
    sn = np.array([[0.0, 0.1, 1.0], [0.0, 0.9, 1.0], [0.2, np.nan, 1.0]])
    sweep = {
        "spacings": spacings,
        "step": [[1.0, 1.1, 1.2]] * 3,
        "step_before": [1.5] * 3,
        "choice": {"step_norm": sn, "time_norm": tn, "index": [1, 1, 0]},
        "spacing": 300.0,
    }
    ax = _fig_sweep(sweep).axes[1]
    labels = {a.get_text(): tuple(map(float, a.xy)) for a in ax.texts}
    # at the point of each spacing nearest (0, 0), a NaN left out
    assert labels == {"100 px": (1.0, 0.0), "300 px": (0.4, 0.1), "1000 px": (0.0, 1.0)}
    for a in ax.texts:  # drawn beside its point, a few points off
        assert a.anncoords == "offset points" and a.xyann == (3, 3)
