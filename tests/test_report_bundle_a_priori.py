"""The bundle report states the stochastic model: the a-priori standard deviations.

Before, neither the report nor its record said with which standard deviations the image
observations, the control points, the GNSS positions and the IMU attitudes were weighted:
a client reading sigma0 could not tell what it was relative to.
"""

from __future__ import annotations

import re

import pytest

import photogeom as pg
from photogeom.report.bundle import (
    bundle_report,
    bundle_result_data,
    read_bundle_result,
    write_bundle_result,
)


@pytest.fixture(scope="module")
def fit():
    sim = pg.simulate.uav_block(
        "FC300S", seed=3, strips=2, images_per_strip=4, tie_points_per_image=60,
        sigma=0.4, gcp_sigma=0.7, survey_sigma=(0.015, 0.025, 0.035),
        gnss_sigma=(0.04, 0.06, 0.08), imu_sigma_deg=0.9,
    )  # fmt: skip
    return pg.bundle_adjust(sim.block)


def test_record_holds_the_sigmas_the_block_was_simulated_with(fit):
    rows = {r["observations"]: r for r in bundle_result_data(fit, angle_unit="gon")["a_priori"]}
    b = fit.block
    expected = {
        "image observations of tie points": (0.4, "px"),
        "image observations of control points": (0.7, "px"),
        "image observations of check points": (0.7, "px"),
        "control points X": (0.015, "m"),
        "control points Y": (0.025, "m"),
        "control points Z": (0.035, "m"),
        "GNSS X0": (0.04, "m"),
        "GNSS Y0": (0.06, "m"),
        "GNSS Z0": (0.08, "m"),
        "IMU omega": (1.0, "gon"),  # 0.9 deg
        "IMU phi": (1.0, "gon"),
        "IMU kappa": (1.0, "gon"),
    }
    assert set(rows) == set(expected)
    for name, (sigma, unit) in expected.items():
        r = rows[name]
        assert r["unit"] == unit
        assert r["median"] == r["min"] == r["max"] == pytest.approx(sigma, rel=1e-12), name
    n_ctl = int((b.role == "control").sum())
    assert rows["control points X"]["n"] == n_ctl
    assert rows["GNSS X0"]["n"] == rows["IMU kappa"]["n"] == b.n_images
    role = b.role[b.obs_point]
    assert (
        sum(rows[f"image observations of {r} points"]["n"] for r in ("tie", "control", "check"))
        == role.size
    )


def test_report_shows_them_and_reads_older_records(fit, tmp_path):
    with pytest.MonkeyPatch.context() as mp:  # the figures are drawn, not encoded (faster)
        mp.setattr("photogeom.report.bundle.figure_to_png", lambda fig, dpi=110: b"")
        text = bundle_report(fit).write(tmp_path / "r.html").read_text(encoding="utf-8")
        part = text[text.index(">A-priori standard deviations</h") :]
        part = part[: part.index("</table>")]
        cells = [re.findall(r"<td[^>]*>(.*?)</td>", r) for r in re.findall(r"<tr>(.*?)</tr>", part)]
        assert ["GNSS Z0", str(fit.block.n_images), "0.08", "0.08", "m"] in cells
        assert any(
            c[:1] == ["image observations of tie points"] and c[2:] == ["0.4", "0.4", "px"]
            for c in cells
        )
        # a record written before the a-priori sigmas were kept renders without them
        data = bundle_result_data(fit)
        del data["a_priori"]
        write_bundle_result(data, tmp_path / "old.json")
        old = read_bundle_result(tmp_path / "old.json")
        out = bundle_report(old).write(tmp_path / "old.html").read_text(encoding="utf-8")
    assert "A-priori standard deviations" not in out and "Calibration" in out
