"""Command line: photogeom bundle simulate | adjust | convert | report."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import photogeom as pg

SMALL = ["--strips", "2", "--images-per-strip", "4", "--tie-points-per-image", "60"]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A simulated CSV block (written by the command) with one blunder."""
    from photogeom.cli.main import main

    d = tmp_path_factory.mktemp("sim") / "block"
    try:
        main(["bundle", "simulate", str(d), "--seed", "5", "--blunders", "1", *SMALL])
    except SystemExit as exc:  # pragma: no cover - a failure shows in the asserts below
        assert exc.code in (0, None)
    return d


def test_help_lists_the_commands():
    from photogeom.cli.main import app

    res = CliRunner().invoke(app, ["bundle", "--help"])
    assert res.exit_code == 0
    for c in ("simulate", "adjust", "convert", "report"):
        assert c in res.output


def test_simulate_writes_block_truth_and_settings(simulated, cli, tmp_path):
    for name in ("cameras.csv", "images.csv", "points.csv", "observations.csv"):
        assert (simulated / name).is_file() and (simulated / "truth" / name).is_file()
    rec = json.loads((simulated / "simulation.json").read_text())
    assert rec["preset"] == "FC300S" and rec["seed"] == 5 and len(rec["blunders"]) == 1
    # the files hold the simulator's blocks: same seed, same block
    sim = pg.simulate.uav_block(
        "FC300S", seed=5, blunders=1, strips=2, images_per_strip=4, tie_points_per_image=60
    )
    block = pg.bundle.read_csv_block(simulated)
    truth = pg.bundle.read_csv_block(simulated / "truth")
    assert block.n_observations == sim.block.n_observations
    np.testing.assert_allclose(block.observations.uv, sim.block.observations.uv, atol=1e-9)
    np.testing.assert_allclose(truth.xyz, sim.truth.xyz, atol=1e-9)
    np.testing.assert_allclose(pg.bundle.reprojection_residuals(truth), 0, atol=1e-6)
    b = rec["blunders"][0]
    r = sim.blunder_rows[0]
    assert (b["image"], b["point"]) == (
        sim.block.observations.image_ids[r].item(),
        sim.block.observations.point_ids[r].item(),
    )
    code, out, err = cli("bundle", "simulate", tmp_path / "j", "--json", "--no-gnss", *SMALL)
    assert code == 0, err
    assert json.loads(out)["options"]["gnss_sigma"] is None


def test_adjust_text_json_outputs_and_report(simulated, cli, tmp_path):
    block = pg.bundle.read_csv_block(simulated)
    ref = pg.bundle.bundle_adjust(block)
    code, out, err = cli("bundle", "adjust", simulated, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["sigma0"] == pytest.approx(ref.sigma0, rel=1e-9)
    assert d["redundancy"] == ref.redundancy and d["unit"] == "m" and d["angle_unit"] == "deg"
    assert d["images"][0]["omega"] == pytest.approx(np.degrees(ref.block.exterior[0, 3]))
    rep, res, outdir = tmp_path / "r.html", tmp_path / "r.json", tmp_path / "adjusted"
    code, out, err = cli(
        "bundle",
        "adjust",
        simulated,
        "--report",
        rep,
        "--result",
        res,
        "-o",
        outdir,
        "--angle-unit",
        "gon",
    )
    assert code == 0, err
    assert f"sigma0 a posteriori {ref.sigma0:.4f}" in out and "omega" in out
    assert "fail the w-test" in out  # the blunder
    adjusted = pg.bundle.read_csv_block(outdir)
    np.testing.assert_allclose(adjusted.exterior, ref.block.exterior, atol=1e-9)
    np.testing.assert_allclose(adjusted.xyz, ref.block.xyz, atol=1e-8)
    html = rep.read_text()
    assert html.startswith("<!DOCTYPE html>") and "Flagged observations (w-test)" in html
    assert "omega ± s [gon]" in html
    # the saved record renders the same report again
    rep2 = tmp_path / "again.html"
    code, out, err = cli(
        "bundle", "report", res, "-o", rep2, "--title", f"Bundle adjustment: {simulated.name}"
    )
    assert code == 0, err
    strip = lambda s: "\n".join(  # noqa: E731
        ln
        for ln in s.splitlines()
        # the version and date, and the command that wrote the file (adjust, then report)
        if not ln.startswith(('<p class="note">photogeom ', '<p class="note">command: '))
    )
    assert strip(rep2.read_text()) == strip(html)


def test_adjust_options_reach_the_adjustment(simulated, cli, tmp_path):
    code, out, err = cli(
        "bundle",
        "adjust",
        simulated,
        "--json",
        "--free",
        "f,k1,k2",
        "--loss",
        "huber",
        "--variance-components",
        "--max-iterations",
        "50",
    )
    assert code == 0, err
    d = json.loads(out)
    assert d["solver"]["loss"] == "huber"
    assert d["variance_components"]["factors"]
    g = next(iter(d["calibration_std"]))
    free = {k for k, v in d["calibration_std"][g].items() if v is not None}
    assert free == {"f", "k1", "k2"}
    code, out, err = cli(
        "bundle",
        "adjust",
        simulated,
        "--point-covariance",
        "--no-snooping",
        "--result",
        tmp_path / "r.json",
    )
    assert code == 0, err
    rec = json.loads((tmp_path / "r.json").read_text())
    assert rec["point_precision"]["n"] > 0 and rec["snooping"] is None


def test_errors_are_one_line_in_option_words(simulated, cli, tmp_path):
    code, _out, err = cli("bundle", "adjust", tmp_path / "nothing")
    assert code == 2 and err.startswith("error: no file or folder")
    code, _, err = cli("bundle", "adjust", simulated, "--free", "f,zz")
    assert code == 2 and err.startswith("error:") and "zz" in err
    code, _, err = cli("bundle", "convert", simulated, tmp_path / "b.txt")
    assert code == 2 and "--drop-extras" in err and "drop_extras=True" not in err
    (tmp_path / "empty").mkdir()
    code, _, err = cli("bundle", "adjust", tmp_path / "empty")
    assert code == 2 and "--format" in err
    code, _, err = cli("bundle", "convert", simulated, tmp_path / "out")
    assert code == 2 and "--to" in err
    # an undetermined camera: the advice names --free, not the keyword of bundle_adjust
    code, _, err = cli("bundle", "adjust", pg.datasets.path("dubrovnik-3-7"), "--datum", "free")
    assert code == 2 and "--free f,cx,cy" in err and "free=(" not in err
    code, _, err = cli("bundle", "adjust", simulated, "--report", tmp_path / "no" / "r.html")
    assert code == 2 and "--report" in err and "does not exist" in err
    bad = tmp_path / "x.json"
    bad.write_text('{"a": 1}')
    code, _, err = cli("bundle", "report", bad)
    assert code == 2 and "not a bundle adjustment result" in err
    code, _, err = cli("bundle", "adjust", bad)
    assert code == 2 and "photogeom bundle report" in err


def test_convert_round_trip_and_free_datum(simulated, cli, tmp_path):
    bal = tmp_path / "b.bal"
    code, out, err = cli("bundle", "convert", simulated, bal, "--drop-extras")
    assert code == 0, err and "(bal)" in out
    code, _, err = cli("bundle", "convert", bal, tmp_path / "col", "--to", "colmap")
    assert code == 0, err
    code, out, err = cli(
        "bundle", "convert", tmp_path / "col", tmp_path / "csv", "--to", "csv", "--json"
    )
    assert code == 0, err
    info = json.loads(out)
    assert info["source_format"] == "colmap" and info["target_format"] == "csv"
    a = pg.bundle.read_bal(bal)
    c = pg.bundle.read_csv_block(tmp_path / "csv")
    assert c.n_observations == a.n_observations
    np.testing.assert_allclose(
        pg.bundle.reprojection_residuals(c), pg.bundle.reprojection_residuals(a), atol=1e-6
    )
    # no control in BAL: the datum defect names the option
    code, _, err = cli("bundle", "adjust", bal)
    assert code == 2 and "--datum free" in err
    out_bal = tmp_path / "adj.bal"
    code, out, err = cli("bundle", "adjust", bal, "--datum", "free", "-o", out_bal)
    assert code == 0, err
    assert "inner-constraint" in out and out_bal.is_file()


def test_progress_on_a_terminal_only(simulated, cli, monkeypatch, terminal_stderr):
    code, _out, err = cli("bundle", "adjust", simulated)
    assert code == 0 and err == ""  # not a terminal: no progress display
    buf = terminal_stderr()
    calls = []
    orig = pg.bundle.bundle_adjust

    def spy(block, *a, progress=None, **k):
        def p(it, cost, lam):
            calls.append(it)
            progress(it, cost, lam)

        return orig(block, *a, progress=p, **k)

    monkeypatch.setattr(pg.bundle, "bundle_adjust", spy)
    code, _out, err = cli("bundle", "adjust", simulated)
    assert code == 0, err
    assert calls and calls == sorted(calls)
    assert "cost" in buf.getvalue()


def test_worked_example_finds_the_blunder_and_fills_the_report():
    from photogeom.examples import get
    from photogeom.report import Report

    rep = Report("examples")
    text = get("bundle-uav").run(rep)
    assert "(the simulated blunder); removed, adjusted again" in text
    assert "chi-square test: passed" in text
    # the comparison with the truth is a table: a header, one row per free parameter with
    # its unit, the difference and its ratio to the standard deviation consistent
    lines = text.splitlines()
    k = next(i for i, x in enumerate(lines) if x.split()[:2] == ["parameter", "estimate"])
    assert lines[k].split()[-1] == "unit" and "estimate - true" in lines[k]
    rows = [x.split() for x in lines[k + 1 : k + 9]]
    assert [r[0] for r in rows] == ["f", "cx", "cy", "k1", "k2", "k3", "p1", "p2"]
    for name, est, true, diff, std, z, unit in rows:
        assert unit == ("px" if name in ("f", "cx", "cy") else "1")
        tol = 1e-4 if unit == "px" else 1e-9
        assert float(diff) == pytest.approx(float(est) - float(true), abs=tol)
        assert float(z) == pytest.approx(float(diff) / float(std), abs=0.01)
        assert abs(float(z)) < 4
    # the decimal points of a unit's numbers line up
    for unit in ("px", "1"):
        cols = {
            x.index(c) + c.index(".")
            for x, r in zip(lines[k + 1 : k + 9], rows)
            if r[-1] == unit
            for c in r[1:2]
        }
        assert len(cols) == 1, (unit, cols)
    for h in (
        "Calibration against the truth",
        "FC300S block: Calibration",
        "FC300S block: Residuals over the sensor",
        "FC300S block: Convergence",
    ):
        assert h in rep.headings


def test_free_datum_on_a_block_with_control_is_refused_in_option_words(simulated, cli):
    """A free network holds the first image: with control, GNSS or IMU in the block it
    would pull against them (it ran and gave sigma0 2.7 on such a block)."""
    code, _, err = cli("bundle", "adjust", simulated, "--datum", "free")
    assert code == 2 and err.startswith("error: --datum free (a free network)")
    assert "--datum weighted" in err and "images.csv" in err
    assert "datum='" not in err and "without_datum_observations" not in err


def test_summary_labels_every_length_with_the_unit_option(simulated, cli):
    """The printed summary labels its object lengths with --unit (default m): the GSD, the
    GNSS residuals, the standard deviations of centres and points, the check-point RMSE."""
    import re

    for args, unit in (((), "m"), (("--unit", "ft"), "ft")):
        code, out, err = cli("bundle", "adjust", simulated, "--point-covariance", *args)
        assert code == 0, err
        assert "object units" not in out
        assert re.search(rf"GSD [0-9.]+ {unit} per px", out), out
        for label in (
            "GNSS residuals",
            "exterior orientation, RMS of the standard deviations",
            "points, RMS of the standard deviations",
            "check points",
        ):
            line = next(x for x in out.splitlines() if x.startswith(label))
            # every X, Y, Z triple ends in the unit: Z0 0.04 m / Z 0.02 m
            assert re.search(rf"Z0? [0-9.e+-]+ {unit}\b", line), line
    # the Python default is the metre, the unit the report and --result use
    fit = pg.bundle.bundle_adjust(pg.bundle.read_csv_block(simulated))
    assert " m per px" in fit.summary() and " ft per px" in fit.summary(unit="ft")


def test_summary_calibration_is_a_table_with_aligned_decimals(simulated, cli):
    """The calibration of the printed summary is a table (parameter, value, std. dev.,
    unit) whose decimal points line up per unit, and whose numbers read back as the
    adjusted calibration (px to 1e-4, distortion to 1e-9)."""
    code, out, err = cli("bundle", "adjust", simulated, "--json")
    assert code == 0, err
    d = json.loads(out)
    cal, std = d["calibration"]["FC300S"], d["calibration_std"]["FC300S"]
    code, out, err = cli("bundle", "adjust", simulated)
    assert code == 0, err
    lines = out.splitlines()
    head = next(k for k, x in enumerate(lines) if x.split()[:1] == ["parameter"])
    assert lines[head].split() == ["parameter", "value", "std.", "dev.", "unit"]
    rows = [x.split() for x in lines[head + 1 : head + 12]]
    assert [r[0] for r in rows] == list(pg.bundle.CALIBRATION_NAMES)
    points: dict[str, set] = {"px": set(), "1": set()}
    for line, (name, value, s, unit) in zip(lines[head + 1 : head + 12], rows):
        assert unit == ("px" if name in ("f", "cx", "cy", "b1", "b2") else "1"), line
        tol = 1e-4 if unit == "px" else 1e-9
        assert float(value) == pytest.approx(cal[name], abs=tol), line
        if std[name] is None:
            assert s == "fixed", line
        else:
            assert float(s) == pytest.approx(std[name], abs=tol), line
        # the value's and the standard deviation's decimal points, per unit
        v_end = line.index(value) + len(value)
        points[unit].add((line.index(value) + value.index("."), v_end))
        if s != "fixed":
            points[unit].add(line.rindex(s) + s.index("."))
    for unit, cols in points.items():
        assert len({c for c in cols if isinstance(c, int)}) == 1, (unit, cols)
        assert len({c for c in cols if isinstance(c, tuple)}) == 1, (unit, cols)


def test_summary_counts_the_flagged_observations_it_does_not_list(tmp_path, cli):
    """The summary lists the 20 largest |w| and says how many more fail the w-test and
    where they all are (before: 69 flagged, 20 lines, nothing about the other 49)."""
    sim = pg.simulate.uav_block(
        "FC300S", seed=5, blunders=2, strips=2, images_per_strip=4, tie_points_per_image=60
    )
    d = tmp_path / "block"
    pg.bundle.write_csv_block(sim.block, d)
    code, out, err = cli("bundle", "adjust", d, "--json")
    assert code == 0, err
    flagged = json.loads(out)["snooping"]["flagged"]
    assert len(flagged) > 20
    code, out, err = cli("bundle", "adjust", d)
    assert code == 0, err
    lines = out.splitlines()
    listed = [x for x in lines if x.startswith("  image ") and "|w| =" in x]
    assert len(listed) == 20
    assert f"{len(flagged)} observation(s) flagged" in out
    more = next(x for x in lines if x.startswith("  ... and "))
    assert more.startswith(f"  ... and {len(flagged) - 20} more") and "--json" in more


def test_a_run_that_did_not_converge_exits_1_after_writing_what_was_asked(
    simulated, cli, tmp_path
):
    # one iteration cannot converge from GNSS/IMU start values (7 iterations are needed):
    # the summary, --json and -o show the last iterate, and the exit code says it is not an
    # adjusted block (a script chaining commands must not go on with it)
    code, out, err = cli("bundle", "adjust", simulated, "--max-iterations", "1",
                         "-o", tmp_path / "last")  # fmt: skip
    assert code == 1, err
    assert "not converged" in out.lower() or "did not converge" in out.lower()
    assert err.strip().splitlines()[-1].startswith("error: the adjustment did not converge")
    assert "--max-iterations" in err and (tmp_path / "last" / "images.csv").is_file()
    code, out, err = cli("bundle", "adjust", simulated, "--max-iterations", "1", "--json")
    assert code == 1 and json.loads(out)["converged"] is False
    code, out, err = cli("bundle", "adjust", simulated, "--json")
    assert code == 0 and json.loads(out)["converged"] is True


def test_converting_to_a_format_without_sigmas_names_the_sigma_not_written(cli, tmp_path):
    # a CSV block whose observations all have 0.3 px: BAL, Bundler and COLMAP hold no
    # standard deviation and their readers take 1 px; the conversion says so and how to read
    # the file back with the same weights (before: nothing was said)
    code, _, err = cli("bundle", "simulate", tmp_path / "s", "--gcps", "none", "--checks", "0",
                       "--no-gnss", "--no-imu", "--gcp-sigma", "0.3", "--strips", "2",
                       "--images-per-strip", "3")  # fmt: skip
    assert code == 0, err
    assert np.all(pg.bundle.read_csv_block(tmp_path / "s").observations.sigma == 0.3)
    for fmt, target in (("bal", "s.bal"), ("colmap-bin", "c"), ("bundler", "b.out")):
        code, _, err = cli("bundle", "convert", tmp_path / "s", tmp_path / target, "--to", fmt)
        assert code == 0, err
        assert "holds no standard deviations" in err and "--sigma 0.3" in err, (fmt, err)
    code, _, err = cli("bundle", "convert", tmp_path / "s.bal", tmp_path / "back", "--to",
                       "csv", "--sigma", "0.3")  # fmt: skip
    assert code == 0 and "standard deviations" not in err
    assert np.all(pg.bundle.read_csv_block(tmp_path / "back").observations.sigma == 0.3)
    code, _, err = cli("bundle", "convert", tmp_path / "s.bal", tmp_path / "again.bal")
    assert code == 0 and "standard deviations" not in err  # 1 px: nothing lost
