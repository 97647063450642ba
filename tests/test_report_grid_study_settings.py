"""The grid report states the grids it evaluates, and calls only a simulated block simulated.

Before, the report gave neither the node spacing nor the smoothness of the grids (a
default ``--spacing`` is not even in the command line it shows), and its summary said
"Simulated re-creations (trends), not the study's data" under a surveyed block too; a block
folder named like one of the study's cameras got the study's published numbers beside it.
"""

from __future__ import annotations

import re

import pytest

import photogeom as pg
from photogeom.report.grid_study import grid_study_report


@pytest.fixture(scope="module")
def study():
    return pg.calibration.run_study(
        "FC300S", seed=1, strips=1, images_per_strip=4, spacing=1000, sweep=None
    )


def _report(study, path, **changes) -> str:
    with pytest.MonkeyPatch.context() as mp:  # the figures are drawn, not encoded (faster)
        mp.setattr("photogeom.report.html.figure_to_png", lambda fig, dpi=110: b"")
        return grid_study_report({**study, **changes}, path).read_text(encoding="utf-8")


def _table(text: str, title: str) -> dict[str, str]:
    part = text[text.index(f">{title}</h") :]
    part = part[: part.index("</table>")]
    cells = re.findall(r"<tr><td>(.*?)</td><td[^>]*>(.*?)</td></tr>", part)
    return dict(cells)


def test_the_grids_settings_are_stated(study, tmp_path):
    text = _report(study, tmp_path / "g.html")
    rows = _table(text, "Grids")
    # 4000 x 3000 px FC300S images at 1000 px: 4 rows and 5 columns of nodes
    assert rows["node spacing"] == "1000 px"
    assert rows["nodes per grid (rows x columns)"] == "4 x 5"
    # 'scaled' smoothness of run_study: 0.1 px x (1000 / 100)^2
    assert rows["smoothness sigma"] == "10 px"
    assert rows["images with a grid"] == "4 of 4"


def test_only_a_simulated_block_is_called_simulated(study, tmp_path):
    text = _report(study, tmp_path / "sim.html")
    assert "Simulated re-creations" in text
    assert "1.4 -&gt; 1.2 (mean)" in text  # the study's published step beside it
    # a surveyed block (the command line marks it) in a folder named like the camera
    text = _report(study, tmp_path / "real.html", preset="FC300S", simulated=False)
    assert "Simulated re-creations" not in text
    assert "1.4 -&gt; 1.2" not in text and "150 px (2 of 5)" not in text
    # a result without a name: a block
    plain = {k: v for k, v in study.items() if k != "preset"}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("photogeom.report.html.figure_to_png", lambda fig, dpi=110: b"")
        text = grid_study_report(plain, tmp_path / "b.html").read_text(encoding="utf-8")
    assert "Simulated re-creations" not in text
