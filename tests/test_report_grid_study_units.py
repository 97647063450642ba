"""The summary table of 'grid report' gives the unit of every step column."""

from __future__ import annotations

import re

import pytest

import photogeom as pg
from photogeom.report.grid_study import grid_study_report


def test_step_columns_name_their_unit(tmp_path):
    # before: 're-matched: after' and 'published' held steps in GSD without saying so
    study = pg.calibration.run_study(
        "FC300S", seed=1, strips=1, images_per_strip=4, spacing=1000, sweep=None
    )
    with pytest.MonkeyPatch.context() as mp:  # the figures are drawn, not encoded (faster)
        mp.setattr("photogeom.report.html.figure_to_png", lambda fig, dpi=110: b"")
        out = grid_study_report(study, tmp_path / "g.html")
    text = out.read_text(encoding="utf-8")
    heads = re.findall(r"<th>(.*?)</th>", re.search(r"<tr>(<th>block</th>.*?)</tr>", text).group(1))
    assert heads == [
        "block",
        "step before -&gt; after (GSD)",
        "re-matched: after (GSD)",
        "published step (GSD)",
        "residual RMS reduction",
        "optimal spacing",
        "published optimum",
    ]
    row = re.search(r"<tr><td>FC300S</td>(.*?)</tr>", text).group(1)
    rematched = re.findall(r"<td[^>]*>(.*?)</td>", row)[1]
    assert rematched == f"{study['rematched']['mean_step_after']:.2f}"  # a step in GSD
