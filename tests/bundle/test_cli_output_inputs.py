"""Outputs of `photogeom bundle`: a target that cannot be written is refused before the work
(named option, exit 2), and a failure while writing leaves nothing written."""

from __future__ import annotations

import json

import pytest

import photogeom.bundle as bundle
from photogeom.bundle import write_csv_block

SMALL = ["--strips", "2", "--images-per-strip", "4", "--tie-points-per-image", "60"]


@pytest.fixture(scope="module")
def block_dir(tmp_path_factory):
    """A simulated CSV block written by the library (not by the command under test)."""
    import photogeom as pg

    sim = pg.simulate.uav_block(
        "FC6310", seed=1, strips=2, images_per_strip=4, tie_points_per_image=60
    )
    d = tmp_path_factory.mktemp("src") / "uav"
    write_csv_block(sim.block, d)
    return d


def _tree(root):
    """Every path under ``root`` (relative), to compare before and after."""
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def _no_adjustment(monkeypatch):
    def refuse(*a, **k):  # pragma: no cover - reached only when the check comes too late
        raise AssertionError("the adjustment ran before the outputs were checked")

    monkeypatch.setattr(bundle, "bundle_adjust", refuse)


def test_adjust_result_onto_a_folder_writes_nothing(block_dir, cli, tmp_path, monkeypatch):
    (tmp_path / "rdir").mkdir()
    _no_adjustment(monkeypatch)
    code, _, err = cli("bundle", "adjust", block_dir, "-o", tmp_path / "OUT", "--result",
                       tmp_path / "rdir")
    assert code == 2 and "--result" in err and "is a folder" in err
    assert _tree(tmp_path) == ["rdir"]


def test_adjust_output_onto_a_file_is_refused_before_adjusting(
    block_dir, cli, tmp_path, monkeypatch
):
    f = tmp_path / "afile"
    f.write_text("keep")
    _no_adjustment(monkeypatch)
    code, _, err = cli("bundle", "adjust", block_dir, "-o", f)
    assert code == 2
    assert err.startswith("error: --output: ") and "is a file, not a folder" in err
    assert "Traceback" not in err and f.read_text() == "keep"


def test_adjust_failure_while_writing_leaves_every_output_as_it_was(block_dir, cli, tmp_path):
    out = tmp_path / "OUT"
    (out / "points.csv").mkdir(parents=True)  # passes the checks, fails in the batch
    code, _, err = cli("bundle", "adjust", block_dir, "-o", out, "--result",
                       tmp_path / "r.json", "--report", tmp_path / "r.html")
    assert code == 2 and "points.csv" in err
    assert _tree(tmp_path) == ["OUT", "OUT/points.csv"]


def test_simulate_json_onto_a_folder_writes_nothing(cli, tmp_path):
    (tmp_path / "S" / "simulation.json").mkdir(parents=True)
    code, _, err = cli("bundle", "simulate", tmp_path / "S", "-p", "FC6310", *SMALL)
    assert code == 2 and "simulation.json" in err
    assert _tree(tmp_path) == ["S", "S/simulation.json"]


def test_simulate_failure_in_truth_writes_nothing(cli, tmp_path):
    (tmp_path / "S" / "truth" / "images.csv").mkdir(parents=True)
    code, _, err = cli("bundle", "simulate", tmp_path / "S", "-p", "FC6310", *SMALL)
    assert code == 2 and "images.csv" in err
    assert _tree(tmp_path) == ["S", "S/truth", "S/truth/images.csv"]


def test_simulate_into_a_new_nested_folder(cli, tmp_path):
    code, _, _ = cli("bundle", "simulate", tmp_path / "a" / "b", "-p", "FC6310", *SMALL)
    assert code == 0
    assert json.loads((tmp_path / "a" / "b" / "simulation.json").read_text())["preset"]
    assert (tmp_path / "a" / "b" / "truth" / "observations.csv").is_file()


@pytest.mark.parametrize("to", ["csv", "colmap"])
def test_convert_onto_a_file(block_dir, cli, tmp_path, to):
    f = tmp_path / "afile"
    f.write_text("keep")
    for target in (f, f / "below"):
        code, _, err = cli("bundle", "convert", block_dir, target, "--to", to, "--drop-extras")
        assert code == 2 and err.startswith("error: TARGET: cannot write")
        assert "is a file, not a folder" in err and "Traceback" not in err
    assert f.read_text() == "keep" and _tree(tmp_path) == ["afile"]


def test_convert_bal_onto_a_folder(block_dir, cli, tmp_path):
    (tmp_path / "x.bal").mkdir()
    code, _, err = cli("bundle", "convert", block_dir, tmp_path / "x.bal", "--drop-extras")
    assert code == 2 and "is a folder" in err
