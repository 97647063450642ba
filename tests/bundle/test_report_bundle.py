"""HTML report of a bundle adjustment: structure, numbers against independent computations,
truncation of big tables, the saved result record and its round trip."""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import FileFormatError
from photogeom.report import Report
from photogeom.report.bundle import (
    RESULT_FORMAT,
    _calibration_section,
    _exterior_section,
    _flagged_section,
    add_bundle_fit,
    bundle_report,
    bundle_result_data,
    read_bundle_result,
    write_bundle_result,
)

FREE = ("f", "cx", "cy", "k1", "k2", "k3", "p1", "p2")


class _Tables(HTMLParser):
    """Headings (h2/h3/h4 text), tables (rows of (text, classes) cells) and images."""

    def __init__(self):
        super().__init__()
        self.headings: list[str] = []
        self.tables: list[list[list[tuple[str, str]]]] = []
        self.images = 0
        self._h = None
        self._cell = None
        self._cls = ""

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag in ("h2", "h3", "h4"):
            self._h = ""
        elif tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell, self._cls = "", a.get("class", "") or ""
        elif tag == "img":
            self.images += 1

    def handle_endtag(self, tag):
        if tag in ("h2", "h3", "h4") and self._h is not None:
            self.headings.append(self._h.strip())
            self._h = None
        elif tag in ("td", "th") and self._cell is not None:
            self.tables[-1][-1].append((self._cell.strip(), self._cls))
            self._cell = None

    def handle_data(self, data):
        if self._h is not None:
            self._h += data
        if self._cell is not None:
            self._cell += data


def _parse(html: str) -> _Tables:
    p = _Tables()
    p.feed(html)
    return p


def _table_after(html: str, heading: str) -> list[list[tuple[str, str]]]:
    """The first table after the heading ``heading``."""
    i = html.index(f">{heading}</h")
    return _parse(html[i:]).tables[0]


@pytest.fixture(scope="module")
def sim():
    return pg.simulate.uav_block(
        "FC300S",
        seed=3,
        strips=2,
        images_per_strip=5,
        tie_points_per_image=80,
        blunders=1,
        blunder_size=60.0,
    )


@pytest.fixture(scope="module")
def fit(sim):
    return pg.bundle.bundle_adjust(sim.block, point_covariance=True, free=FREE)


@pytest.fixture(scope="module")
def html(fit):
    return bundle_report(fit, "Bundle").to_html()


def test_sections_and_figures(html):
    p = _parse(html)
    for h in (
        "Adjustment summary",
        "Calibration",
        "Exterior orientation",
        "Control and check points",
        "Residuals over the sensor",
        "Residual RMS per image",
        "Point precision",
        "Convergence",
        "Flagged observations (w-test)",
        "Notes",
        "Control points (5)",
        "Check points (4)",
    ):
        assert h in p.headings, h
    # heat map, sensor grid, per-image RMS, point precision, convergence
    assert p.images == 5
    assert "Variance components" not in p.headings  # not estimated


def test_summary_numbers(fit, html):
    rows = dict((r[0][0], r[1][0]) for r in _table_after(html, "Adjustment summary"))
    assert float(rows["sigma0 a posteriori"]) == pytest.approx(fit.sigma0, rel=1e-3)
    assert rows["redundancy r"] == str(fit.redundancy)
    assert rows["observations / unknowns"] == f"{fit.n_observations} / {fit.n_unknowns}"
    assert rows["chi-square test of v'Pv / sigma0_prior^2"].startswith(
        "passed" if fit.chi2["passed"] else "FAILED"
    )
    assert rows["solver"].startswith(fit.solver["backend"])
    assert "px" in rows["RMS image residual"] and "m/px" in rows["mean GSD"]


def test_calibration_table_and_flags(fit, html):
    t = _table_after(html, "Calibration")
    assert [c[0] for c in t[0]] == ["parameter", "value", "std. dev.", "unit"]
    body = {r[0][0]: r for r in t[1:]}
    g = next(iter(fit.calibration))
    assert float(body["f"][1][0]) == pytest.approx(fit.calibration[g]["f"], abs=0.01)
    assert float(body["f"][2][0]) == pytest.approx(fit.calibration_std[g]["f"], rel=0.05)
    assert body["k4"][2][0] == "fixed" and body["b1"][3][0] == "px" and body["k1"][3][0] == "1"
    # the pairs above 0.9 of the correlation matrix, computed here from the covariance
    names, C = fit.calibration_covariance(g)
    d = np.sqrt(np.diag(C))
    R = C / np.outer(d, d)
    pairs = {
        (names[i], names[j])
        for i in range(len(names))
        for j in range(i + 1, len(names))
        if abs(R[i, j]) > 0.9
    }
    if pairs:
        rows = _table_after(html, f"Correlations with |rho| &gt; 0.9 ({len(pairs)})")
        assert {(r[1][0], r[2][0]) for r in rows[1:]} == pairs
        assert all("flag" in r[3][1] for r in rows[1:])


def test_exterior_table_all_images_in_order(fit, html):
    t = _table_after(html, "Exterior orientation")
    # one camera group: no camera column
    assert t[0][1][0] == "X0 ± s [m]" and t[0][4][0] == "omega ± s [deg]"
    assert [r[0][0] for r in t[1:]] == [str(i) for i in fit.block.image_ids.tolist()]
    k = 3
    x0 = float(t[1 + k][1][0].split("±")[0])
    assert x0 == pytest.approx(fit.block.exterior[k, 0], abs=0.01)
    kappa = float(t[1 + k][6][0].split("±")[0])
    assert kappa == pytest.approx(np.degrees(fit.block.exterior[k, 5]), abs=0.01)


def test_big_blocks_show_the_worst_images(fit):
    html = _exterior_section(bundle_result_data(fit), 3)
    t = _parse(html).tables[0]
    assert len(t) == 1 + 3
    # RMS per image computed here from the residual rows
    b = fit.block
    v = fit.residuals[fit.in_adjustment]
    img = b.obs_image[fit.in_adjustment]
    rms = np.array([np.sqrt(np.mean(np.sum(v[img == i] ** 2, axis=1))) for i in range(b.n_images)])
    worst = [str(b.image_ids[i]) for i in np.argsort(-rms)[:3]]
    assert [r[0][0] for r in t[1:]] == worst
    assert f"the 3 of {b.n_images} images with the largest RMS residual" in html


def test_control_and_check_tables(sim, fit, html):
    t = _table_after(html, "Control points (5)")
    blk, adj = sim.block, fit.block
    for row in t[1:-1]:
        pid = int(row[0][0])
        j = list(blk.point_ids).index(pid)
        d = adj.xyz[j] - blk.xyz[j]
        assert [float(c[0]) for c in row[1:4]] == pytest.approx(d, abs=6e-5)
        assert float(row[5][0]) == pytest.approx(np.linalg.norm(d) / fit.gsd, abs=0.006)
    assert t[-1][0][0] == "RMSE"
    c = _table_after(html, "Check points (4)")
    errs = np.asarray(fit.check["errors"])
    for row, e in zip(c[1:-1], errs):
        assert [float(x[0]) for x in row[1:4]] == pytest.approx(e, abs=6e-5)


def test_flagged_observation_is_the_blunder(sim, fit, html):
    r = sim.blunder_rows[0]
    o = sim.block.observations
    t = _table_after(html, "Flagged observations (w-test)")
    first = t[1]
    assert (first[0][0], first[1][0]) == (str(o.image_ids[r]), str(o.point_ids[r]))
    assert "flag" in first[2][1]
    assert float(first[3][0]) == pytest.approx(fit.residuals[r, 0], abs=1e-3)


def test_sensor_grid_means_match_a_cell_by_cell_count(fit):
    d = bundle_result_data(fit, cells=6)
    g = d["sensor_grid"][0]
    b = fit.block
    w, h = b.calibrations[0].width, b.calibrations[0].height
    assert (g["nx"], g["ny"]) == (6, round(6 * h / w))
    uv = b.observations.uv[fit.in_adjustment]
    v = fit.residuals[fit.in_adjustment]
    nx, ny = g["nx"], g["ny"]
    for k in range(nx * ny):
        iy, ix = divmod(k, nx)
        u0, u1 = ix * w / nx - 0.5, (ix + 1) * w / nx - 0.5
        v0, v1 = iy * h / ny - 0.5, (iy + 1) * h / ny - 0.5
        sel = (uv[:, 0] >= u0) & (uv[:, 0] < u1) & (uv[:, 1] >= v0) & (uv[:, 1] < v1)
        assert g["count"][k] == int(sel.sum())
        if sel.any():
            assert g["mean"][k] == pytest.approx(v[sel].mean(axis=0), abs=1e-12)
        else:
            assert g["mean"][k] == [None, None]
    assert sum(g["count"]) == g["n_observations"] == int(fit.in_adjustment.sum())


def test_point_histogram_counts_every_point(fit):
    pp = bundle_result_data(fit)["point_precision"]
    n = int(np.sum(fit.block.role != "check"))
    assert pp["n"] == n
    for a in "XYZ":
        assert sum(pp["counts"][a]) == n
    assert pp["rms"] == pytest.approx(
        np.sqrt(np.mean(fit.point_std[fit.block.role != "check"] ** 2, axis=0))
    )


def test_record_round_trip_gives_the_same_report(fit, html, tmp_path):
    data = bundle_result_data(fit)
    assert data["format"] == RESULT_FORMAT
    path = write_bundle_result(data, tmp_path / "r.json")
    back = read_bundle_result(path)
    strip = re.compile(r'<p class="note">photogeom [^<]*</p>')
    assert strip.sub("", bundle_report(back, "Bundle").to_html()) == strip.sub("", html)


def test_bad_result_files(tmp_path):
    p = tmp_path / "x.json"
    p.write_text("{not json")
    with pytest.raises(FileFormatError, match="not JSON"):
        read_bundle_result(p)
    p.write_text(json.dumps({"sigma0": 1}))
    with pytest.raises(FileFormatError, match="not a bundle adjustment result"):
        read_bundle_result(p)
    p.write_text(json.dumps({"format": RESULT_FORMAT, "version": 99}))
    with pytest.raises(FileFormatError, match="version 99"):
        read_bundle_result(p)


def test_without_point_covariance_or_snooping(sim):
    fit = pg.bundle.bundle_adjust(sim.block, free=FREE, snooping=False)
    data = bundle_result_data(fit)
    assert data["point_precision"] is None and data["flagged"] == []
    assert "Data snooping was not run" in _flagged_section(data, 50)


def test_variance_components(sim, monkeypatch):
    import photogeom.report.bundle as rb

    fit = pg.bundle.bundle_adjust(sim.block, free=FREE, variance_components=True, snooping=False)
    monkeypatch.setattr(rb, "figure_to_png", lambda fig: b"")  # tables only: faster
    rep = Report("x")
    data = add_bundle_fit(rep, fit, "VC")
    html = rep.to_html()
    assert "Point covariances were not computed" in html
    assert rep.headings[0] == "VC: Adjustment summary"
    t = _table_after(html, "VC: Variance components")
    groups = {r[0][0]: float(r[1][0]) for r in t[1:]}
    assert [c[0] for c in t[0]][:3] == ["observation group", "sigma factor", "variance factor"]
    assert groups.keys() == fit.variance_components["factors"].keys()
    for k, v in groups.items():
        assert v == pytest.approx(fit.variance_components["factors"][k], abs=1e-4)
    assert data["variance_components"]["rounds"] == fit.variance_components["rounds"]


def test_many_camera_groups_are_pooled(tmp_path):
    cam = pg.MetashapeCalibration(4000, 3000, 2240.0, k1=-0.1, k2=0.09)
    sim = pg.simulate.uav_block(
        "FC300S", seed=2, strips=2, images_per_strip=4, tie_points_per_image=60, true_camera=cam
    )
    bal = tmp_path / "b.txt"
    pg.bundle.write_bal(sim.truth, bal, drop_extras=True)
    block = pg.bundle.read_bal(bal)  # one camera group per image
    fit = pg.bundle.bundle_adjust(block, datum="free", max_iterations=10)
    # free network: every image has standard deviations in the inner-constraint datum (the
    # images held for the minimal constraints too), the same as its covariance block
    cov = np.array([np.sqrt(np.diag(fit.image_covariance(i))) for i in block.image_ids.tolist()])
    np.testing.assert_allclose(fit.exterior_std, cov, rtol=1e-12)
    assert np.all(fit.exterior_std > 0)
    d = bundle_result_data(fit)
    assert len(d["sensor_grid"]) == 1 and d["sensor_grid"][0]["n_images"] == block.n_images
    assert "pooled over camera groups" in d["sensor_grid"][0]["label"]
    e = _parse(_exterior_section(d, 50)).tables[0]
    assert [c[0] for c in e[0][:3]] == ["image", "camera", "X0 ± s [m]"]
    t = _parse(_calibration_section(d, 5)).tables[0]
    assert [c[0] for c in t[0]] == ["camera", "f [px]", "k1 [1]", "k2 [1]"]
    assert len(t) == 1 + 5
