"""The grid-size figure of 'grid report' explains its points in a legend."""

from __future__ import annotations

import numpy as np

from photogeom.report.grid_study import _fig_sweep


def test_cost_against_accuracy_panel_has_a_legend():
    # before: grey curves, red dots and spacing numbers without a legend, so the reader could
    # not tell that each curve is one stereo model and each red dot that model's choice
    sn = np.array([[1.0, 0.4, 0.0], [1.0, 0.5, 0.1], [1.0, 0.0, 0.2]])
    tn = np.array([[0.0, 0.3, 1.0]] * 3)
    sweep = {
        "spacings": [1000.0, 500.0, 200.0],
        "step": [[1.4, 1.2, 1.0]] * 3,
        "step_before": [1.5, 1.5, 1.5],
        "choice": {"step_norm": sn, "time_norm": tn, "index": [1, 1, 1]},
        "spacing": 500.0,
    }
    _, ax = _fig_sweep(sweep).axes
    legend = ax.get_legend()
    assert legend is not None
    assert [t.get_text() for t in legend.get_texts()] == [
        "one stereo model (3)",
        "its spacing closest to (0, 0)",
    ]
    assert sorted(t.get_text() for t in ax.texts) == ["1000 px", "200 px", "500 px"]
    assert ax.get_xlabel() == "normalised CPU time (grid fit and correction)"
