"""The report of ``grid fit --report`` states the grids' settings.

Before, it gave the node spacing in its subtitle and nothing of the smoothness (the
``--sigma-constraint`` that decides how far the grids follow the residuals), of the node
layout or of the images fitted, so that a report handed on could not be reproduced.
"""

from __future__ import annotations

import re

import numpy as np


def test_grid_fit_report_has_the_settings_table(cli, tmp_path):
    rng = np.random.default_rng(5)
    rows = []
    for img in ("a", "b", "c"):
        uv = rng.uniform([0, 0], [599, 399], (150, 2))
        rows += [f"{img},{u},{v},{0.1 + 1e-4 * u},{0.2 - 1e-4 * v}\n" for u, v in uv]
    src = tmp_path / "res.csv"
    src.write_text("image_id,u,v,rx,ry\n" + "".join(rows))
    code, _, err = cli(
        "grid", "fit", src, "--image-size", "600x400", "--spacing", "100", "--sigma-constraint",
        "2.5", "--exclude", "c", "-o", tmp_path / "g.npz", "--report", tmp_path / "r.html",
    )  # fmt: skip
    assert code == 0, err
    text = (tmp_path / "r.html").read_text(encoding="utf-8")
    part = text[text.index(">Grids</h") :]
    part = part[: part.index("</table>")]
    cells = dict(re.findall(r"<tr><td>(.*?)</td><td[^>]*>(.*?)</td></tr>", part))
    # 600 x 400 px at 100 px: 5 rows and 7 columns of nodes
    assert cells == {
        "node spacing": "100 px",
        "nodes per grid (rows x columns)": "5 x 7",
        "smoothness sigma": "2.5 px",
        "images with a grid": "2",
    }
