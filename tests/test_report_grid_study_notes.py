"""The grid report shows the re-adjustment's notes.

Before, ``grid_study_report`` (``photogeom grid report``) left out the notes of the
re-adjustment (``refit.notes``): why its sigma0 is over the chain's effective redundancy or
its own, and that its standard deviations are in-sample. The report now has a section
"Notes of the re-adjustment": the library's notes, or the result's ``notes`` when given
(the command line gives them in its words, as ``grid evaluate`` prints them).
"""

from __future__ import annotations

import html
import re

import pytest

import photogeom as pg
from photogeom.calibration.blocks import IN_SAMPLE_NOTE
from photogeom.report.grid_study import grid_study_report

TITLE = "Notes of the re-adjustment"


@pytest.fixture
def no_png(monkeypatch):
    """The figures are drawn, not encoded (faster)."""
    monkeypatch.setattr("photogeom.report.html.figure_to_png", lambda fig, dpi=110: b"")


def _section(text: str) -> list[str]:
    part = text[text.index(f">{TITLE}</h3>") :]
    part = part[: part.index("</section>")]
    return [html.unescape(p) for p in re.findall(r"<p>(.*?)</p>", part, flags=re.S)]


def test_the_library_report_shows_the_refit_notes(no_png, tmp_path):
    study = pg.calibration.run_study(
        "FC300S", seed=1, strips=1, images_per_strip=4, spacing=1000, sweep=None
    )
    assert IN_SAMPLE_NOTE in study["refit"].notes  # the grids fitted to these residuals
    text = grid_study_report(study, tmp_path / "g.html").read_text(encoding="utf-8")
    assert _section(text) == list(study["refit"].notes)
    # the caller's words replace the library's
    text = grid_study_report({**study, "notes": ["in other words"]}, tmp_path / "h.html")
    assert _section(text.read_text(encoding="utf-8")) == ["in other words"]
    # a re-adjustment without notes: no section
    text = grid_study_report({**study, "notes": []}, tmp_path / "i.html")
    assert f">{TITLE}<" not in text.read_text(encoding="utf-8")


def test_grid_report_shows_the_notes_grid_evaluate_prints(cli, no_png, tmp_path):
    common = ("--preset", "FC300S", "--strips", "1", "--images", "3", "--spacing", "500")
    code, out, err = cli("grid", "report", *common, "--spacings", "500,1000", "--repeats", "1",
                         "-o", tmp_path / "r.html")  # fmt: skip
    assert code == 0, err
    shown = _section((tmp_path / "r.html").read_text(encoding="utf-8"))
    code, out, err = cli("grid", "evaluate", *common, "--json")
    assert code == 0, err
    import json

    assert shown == json.loads(out)["notes"]
    assert "the redundancy marked effective" in shown[0]
    assert "effective_redundancy" not in shown[0]
