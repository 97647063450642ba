"""The residual-grid report draws image vectors as they are in the image: u right, v down
(the sensor's own axes), like the bundle report's sensor figures."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

from photogeom.report.grid_study import _quiver


@pytest.mark.parametrize(("v", "right", "down"), [((0.0, 1.0), 0, 1), ((1.0, 0.0), 1, 0),
                                                   ((1.0, -1.0), 1, -1)])
def test_a_vector_points_where_it_points_in_the_image(v, right, down):
    """It was drawn with v negated on an inverted axis: mirrored top to bottom."""
    fig, ax = plt.subplots()
    try:
        _quiver(ax, np.array([[500.0, 300.0]]), np.array([v]), None, (1000, 600), "t")
        fig.canvas.draw()
        q = ax.collections[0]
        start = ax.transData.transform([500.0, 300.0])
        end = ax.transData.transform([500.0 + q.U[0], 300.0 + q.V[0]])
        d = end - start  # display coordinates: x right, y up
        assert np.sign(np.round(d[0], 6)) == right
        assert np.sign(np.round(-d[1], 6)) == down
    finally:
        plt.close(fig)
