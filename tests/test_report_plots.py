"""Ids, camera names and labels containing ``$`` in report figures: drawn as plain text
(matplotlib would read them as mathtext: a parse error, or math instead of the id)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg
from photogeom.report.bundle import (
    bundle_report,
    bundle_result_data,
    correlation_figure,
    image_rms_figure,
    point_precision_figure,
    sensor_grid_figure,
)
from photogeom.report.plots import plain, residual_figure

matplotlib = pytest.importorskip("matplotlib")

IDS = ["$a^$", "$b$", "$c_{$", "d", "a\\$b$", "$$"]


def _drawn(fig):
    """Every visible text artist of ``fig`` after drawing it (Agg), as (artist, text)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    texts = [(t, t.get_text()) for t in fig.findobj(Text) if t.get_visible() and t.get_text()]
    return texts, canvas.get_renderer()


def _literal_extent(text, like, renderer):
    """(width, height) of ``text`` drawn with mathtext off, in the font and rotation of the
    artist ``like``."""
    from matplotlib.text import Text

    t = Text(
        0,
        0,
        text,
        parse_math=False,
        fontproperties=like.get_fontproperties(),
        rotation=like.get_rotation(),
    )
    t.set_figure(like.get_figure())
    box = t.get_window_extent(renderer)
    return box.width, box.height


def _check_literal(fig, expected):
    """Each expected string is drawn by some text artist exactly as the plain text (the
    same size as the text drawn with mathtext off)."""
    texts, renderer = _drawn(fig)
    for want in expected:
        hits = [t for t, s in texts if s == plain(want)]
        assert hits, (want, [s for _, s in texts])
        for t in hits:
            box = t.get_window_extent(renderer)
            assert (box.width, box.height) == pytest.approx(
                _literal_extent(want, t, renderer), abs=0.01
            ), want


@pytest.mark.parametrize("text", IDS)
def test_plain_leaves_no_mathtext(text):
    from matplotlib.text import Text

    t = Text(0, 0, plain(text))
    drawn, is_math = t._preprocess_math(t.get_text())
    assert (drawn, is_math) == (text, False)


def test_residual_figure_ids_title_labels_unit():
    pts = np.array([[0.0, 0.0], [100, 0], [0, 100], [100, 100], [50, 50], [20, 70]])
    res = np.array([[0.1, 0.0], [0.0, 0.2], [-0.1, 0.1], [0.05, -0.05], [0.0, 0.1], [0.1, 0.1]])
    fig = residual_figure(
        pts,
        res,
        IDS,
        unit="$u$",
        labels=("$E$", "N$"),
        title="file $x$.csv",
        check_points=pts[:2] + 5,
        check_residuals=res[:2],
        check_ids=["$k^$", "$k2$"],
    )
    _check_literal(fig, [*IDS, "$k^$", "$k2$", "$E$ [$u$]", "N$ [$u$]"])


def test_bundle_figures_with_dollar_ids():
    images = [{"id": t, "rms_px": 0.5 + 0.1 * k} for k, t in enumerate(IDS)]
    _check_literal(image_rms_figure(images, 0.6), IDS)
    names = ["$f$", "c$x", "$k_1$"]
    R = np.eye(3) + 0.9 * (1 - np.eye(3))
    _check_literal(correlation_figure(names, R.tolist(), 0.8, "camera $c^$"), names)
    hist = {"edges": [0.0, 1.0, 2.0], "counts": {"X": [1, 2], "Y": [2, 1], "Z": [0, 3]}}
    _check_literal(point_precision_figure(hist, "$m"), ["standard deviation [$m]"])
    grid = {
        "label": "camera $c_{$",
        "width": 400,
        "height": 300,
        "nx": 2,
        "ny": 2,
        "mean": [[0.1, 0.0], [0.0, 0.1], [0.2, 0.1], [0.1, 0.2]],
        "count": [50, 50, 50, 50],
        "n_observations": 200,
        "n_images": 3,
        "rms": 0.3,
    }
    texts, _ = _drawn(sensor_grid_figure([grid]))
    assert any(s.startswith(plain("camera $c_{$: 200 obs.")) for _, s in texts)


@pytest.fixture(scope="module")
def dollar_result():
    sim = pg.simulate.uav_block(
        "FC300S", seed=3, strips=2, images_per_strip=3, tie_points_per_image=40
    )
    fit = pg.bundle.bundle_adjust(sim.block, point_covariance=True, free=("f", "cx", "cy", "k1"))
    d = bundle_result_data(fit)
    d = json.loads(json.dumps(d).replace("FC300S", "$c_{$"))  # the camera name everywhere
    for k, row in enumerate(d["images"]):
        row["id"] = IDS[k % len(IDS)] + str(k)
    return d


def test_bundle_report_with_dollar_camera_and_image_ids(dollar_result):
    html = bundle_report(dollar_result, "Bundle $x$").to_html()
    assert "$c_{$" in html and "$a^$0" in html


def test_cli_transform_report_with_dollar_ids(cli, tmp_path):
    csv = tmp_path / "dollar.csv"
    csv.write_text(
        "id,x,y,X,Y\n$a^$,0,0,10,20\n$b$,100,0,110,21\n$c_{$,0,100,9,120\nd,100,100,111,119\n"
    )
    out = tmp_path / "d.html"
    code, _out, err = cli("transform", "estimate", "similarity2d", csv, "--report", out)
    assert code == 0, err
    html = out.read_text()
    assert "$a^$" in html and "$c_{$" in html and "<img" in html
