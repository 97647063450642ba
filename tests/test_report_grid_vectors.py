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


def test_ids_with_dollars_are_drawn_as_text():
    """An image id or model pair with '$' was read as mathtext: '$a^$' failed to parse and
    took the whole report with it."""
    from photogeom.report.plots import plain

    fig, ax = plt.subplots()
    try:
        _quiver(ax, np.array([[500.0, 300.0]]), np.array([[1.0, 0.0]]), None, (1000, 600),
                "image $a^$: tie-point residuals")
        ax.set_xticks([0])
        ax.set_xticklabels([plain("$b_{$-$c$")])
        fig.canvas.draw()  # raised a mathtext parse error before
        assert ax.get_title() == "image \\$a^\\$: tie-point residuals"
    finally:
        plt.close(fig)


def test_correcting_images_on_a_dashboard_address_is_a_named_error(tmp_path):
    """correct_folder(dask="http://...") gave distributed's raw ValueError (and a silent
    server hung for ever); the address is checked as everywhere else."""
    from photogeom.calibration.images import correct_folder
    from photogeom.errors import InputError

    (tmp_path / "in").mkdir()
    with pytest.raises(InputError, match="dashboard"):
        correct_folder(tmp_path / "in", tmp_path / "out", {}, dask="http://127.0.0.1:8787")
