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


def test_image_residuals_with_blunders_keep_the_others_visible():
    """A grid study's tie-point residual panel scaled the arrows to the longest: three 8 px
    mismatches among 2000 residuals of 0.3 px drew the others at 0.35 % of the image width
    (median). The scale now follows the 90th percentile; the three are clipped, in their own
    colour, and counted in the title; the scale arrow's label is its drawn length."""
    from matplotlib.colors import to_rgba

    from photogeom.report.plots import CLIPPED_COLOUR

    rng = np.random.default_rng(3)
    w, h = 4000, 3000
    uv = rng.uniform([0, 0], [w, h], (2000, 2))
    r = rng.normal(0, 0.3, (2000, 2))
    r[:3] = [[8.0, 0.0], [0.0, 8.0], [-6.0, 5.0]]
    fig, ax = plt.subplots()
    try:
        _quiver(ax, uv, r, None, (w, h), "image 1: tie-point residuals")
        ordinary, clipped, key = ax.collections[:3]
        assert ordinary.N == 1997 and clipped.N == 3
        # drawn in data units (scale 1): median length against the image width
        assert np.median(np.hypot(ordinary.U, ordinary.V)) / w > 0.015
        assert np.allclose(clipped.get_facecolor()[0], to_rgba(CLIPPED_COLOUR))
        clip = 3 * np.quantile(np.hypot(r[:, 0], r[:, 1]), 0.9)
        k = ordinary.U[0] / r[3, 0]  # the exaggeration of the drawn arrows
        assert np.allclose(np.hypot(clipped.U, clipped.V), clip * k)
        assert f"3 longer than {clip:.3g} px clipped" in ax.get_title()
        (label,) = [t.get_text() for t in ax.texts if t.get_text().endswith(" px")]
        assert key.U[0] / k == pytest.approx(float(label.split()[0]))
    finally:
        plt.close(fig)
