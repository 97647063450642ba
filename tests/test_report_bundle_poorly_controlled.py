"""The bundle adjustment report lists the poorly controlled observations with their
redundancy numbers and minimal detectable biases."""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import pytest

import photogeom as pg
from photogeom.report.bundle import bundle_report, bundle_result_data

sys.path.insert(0, str(Path(__file__).parent))
from html_tables import table_rows


@pytest.fixture(scope="module")
def no_png():
    """The figures are drawn but not rendered to PNG (the slow part; not what is tested)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("photogeom.report.bundle.figure_to_png", lambda fig, dpi=110: b"")
        yield


@pytest.fixture(scope="module")
def adjusted(no_png):
    sim = pg.simulate.uav_block(
        "FC300S", seed=3, strips=2, images_per_strip=4, tie_points_per_image=60, local_field=0.0
    )
    fit = pg.bundle_adjust(sim.block)
    data = bundle_result_data(fit)
    return fit, data, bundle_report(data, max_rows=10).to_html()


def _section(text: str, heading: str) -> str:
    start = text.index(f">{heading}</h3>")
    return text[start : text.index("</section>", start)]


def test_the_section_lists_the_observations_the_adjustment_names(adjusted):
    # before: only a note counted them ("they are listed in snooping['poorly_controlled']"),
    # which the report does not show
    fit, _, text = adjusted
    named = {tuple(x) for x in fit.snooping["poorly_controlled"]}
    assert len(named) > 10  # points seen in two images have r ~ 0 along the base
    part = _section(text, "Poorly controlled observations")
    assert f"<strong>{len(named)}</strong>" in part
    assert f"the 10 least controlled of {len(named)}" in part
    rows = [r for r in re.findall(r"<tr>(.*?)</tr>", part) if "<td" in r]
    assert len(rows) == 10
    cells = [[re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<td[^>]*>.*?</td>", r)] for r in rows]
    shown = [(int(c[0]), int(c[1])) for c in cells]
    assert set(shown) <= named
    r_min = [min(float(c[2]), float(c[3])) for c in cells]
    assert r_min == sorted(r_min) and max(r_min) < 0.1
    assert 'href="#poorly-controlled-observations"' in text  # in the contents


def test_mdb_is_delta0_over_sqrt_r(adjusted):
    # Baarda: MDB = delta0 / sqrt(r) a-priori sigmas, delta0 = 4.13 at alpha 0.001, power 80 %
    _, data, _ = adjusted
    assert data["snooping"]["alpha"] == 0.001
    for row in data["poorly_controlled"]:
        for r, mdb in zip(row["r"], row["mdb"]):
            if r > 1e-6:
                assert mdb == pytest.approx(4.13 / math.sqrt(r), rel=2e-3)


def test_a_record_without_the_list_renders_without_the_section(adjusted, no_png):
    _, data, _ = adjusted
    old = {k: v for k, v in data.items() if k not in ("poorly_controlled", "n_poorly_controlled")}
    text = bundle_report(old).to_html()
    assert "Poorly controlled observations" not in text
    assert table_rows(text)["redundancy r"] == [str(data["redundancy"])]


def test_max_rows_of_bundle_report_limits_the_section(cli, adjusted, tmp_path):
    from photogeom.report.bundle import write_bundle_result

    _, data, _ = adjusted
    rec, out = tmp_path / "r.json", tmp_path / "r.html"
    write_bundle_result(data, rec)
    code, _, err = cli("bundle", "report", rec, "-o", out, "--max-rows", "3")
    assert code == 0, err
    part = _section(out.read_text(encoding="utf-8"), "Poorly controlled observations")
    assert len(re.findall(r"<tr><td>", part)) == 3
    assert f"the 3 least controlled of {data['n_poorly_controlled']}" in part
    code, text, _ = cli("bundle", "report", "--help")
    assert "poorly controlled" in " ".join(text.split())  # the help names the table it limits


def test_an_observation_with_r_zero_is_undetectable(adjusted, no_png):
    # the MDB of r = 0 is infinite, which the JSON record holds as null: it read "-"
    _, data, _ = adjusted
    rows = [dict(r) for r in data["poorly_controlled"]]
    rows[0] = {**rows[0], "r": [0.0, rows[0]["r"][1]], "mdb": [None, rows[0]["mdb"][1]]}
    text = bundle_report({**data, "poorly_controlled": rows}).to_html()
    first = re.search(r"<tr><td>[^<]*</td><td>[^<]*</td>(.*?)</tr>",
                      _section(text, "Poorly controlled observations")).group(1)  # fmt: skip
    cells = re.findall(r"<td[^>]*>(.*?)</td>", first)
    assert cells[0] == "0.000" and cells[2:4] == ["undetectable", "undetectable"]


def test_the_note_points_to_the_section_not_to_a_python_key(adjusted):
    # before: "they are listed in snooping['poorly_controlled']", a key of a Python mapping,
    # in a report handed to a client
    fit, _, text = adjusted
    notes = _section(text, "Notes")
    assert "snooping[" not in text
    assert "image observation(s) are poorly controlled" in notes
    assert "they are listed under Poorly controlled observations" in notes
    # the library's own note keeps its key
    assert any("snooping['poorly_controlled']" in n for n in fit.notes)


def test_the_note_and_the_section_name_image_coordinates_alike(adjusted):
    # before: the note said "a redundancy number below 0.1 in x or y" and the section above
    # it "in u or v": the bundle's image observations are (u, v) pixels
    fit, _, text = adjusted
    note = next(n for n in fit.notes if "poorly controlled" in n)
    assert "redundancy number below 0.1 in u or v" in note
    assert "x or y" not in note
    assert "redundancy number r below 0.1 in u or v" in _section(
        text, "Poorly controlled observations"
    )
    notes = _section(text, "Notes")
    assert "below 0.1 in u or v" in notes and "x or y" not in notes
