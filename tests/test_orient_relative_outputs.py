"""``orient relative --output-cameras`` was checked alone: a camera file named
like ``--report`` or ``--output`` was found only when the files were written, after the
computation, by file name (``error: x.out and x.out are the same file``), and one named
like the input MATCHES replaced the points with camera JSON (exit 0). Each camera file is now
checked with the other options and the inputs before the computation, by option name."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from photogeom import datasets

ARGS = ("--f", "100", "--unit", "px", "--method", "independent")


@pytest.fixture
def points(tmp_path: Path) -> Path:
    p = tmp_path / "pts.csv"
    shutil.copyfile(datasets.path("lecture_two_images"), p)
    return p


def test_a_camera_file_named_like_the_report(cli, points: Path, tmp_path: Path):
    same = tmp_path / "x.out"
    code, _, err = cli("orient", "relative", points, *ARGS, "--report", same,
                       "--output-cameras", same, tmp_path / "c2.json")
    assert code == 2
    assert f"--report and --output-cameras both name {same}" in err
    assert not same.exists() and not (tmp_path / "c2.json").exists()


def test_a_camera_file_named_like_the_output(cli, points: Path, tmp_path: Path):
    same = tmp_path / "m.csv"
    code, _, err = cli("orient", "relative", points, *ARGS, "-o", same,
                       "--output-cameras", tmp_path / "c1.json", same)
    assert code == 2
    assert f"--output and --output-cameras both name {same}" in err


def test_a_camera_file_named_like_the_input_keeps_the_points(cli, points: Path, tmp_path: Path):
    before = points.read_bytes()
    code, _, err = cli("orient", "relative", points, *ARGS,
                       "--output-cameras", points, tmp_path / "c2.json")
    assert code == 2
    assert f"--output-cameras {points} is the input file MATCHES" in err
    assert points.read_bytes() == before


def test_the_two_cameras_through_another_spelling(cli, points: Path, tmp_path: Path):
    (tmp_path / "sub").mkdir()
    code, _, err = cli("orient", "relative", points, *ARGS,
                       "--output-cameras", tmp_path / "c.json", tmp_path / "sub" / ".." / "c.json")
    assert code == 2
    assert "--output-cameras: give two different files" in err


def test_distinct_files_are_written(cli, points: Path, tmp_path: Path):
    c1, c2, rep = tmp_path / "c1.json", tmp_path / "c2.json", tmp_path / "r.html"
    code, _, err = cli("orient", "relative", points, *ARGS, "--output-cameras", c1, c2,
                       "--report", rep)
    assert code == 0, err
    assert c1.is_file() and c2.is_file() and rep.is_file()


def test_the_first_argument_is_matches_as_in_the_docs(cli, points: Path, tmp_path: Path):
    # the errors and the usage line called it POINTS ({points}) where docs/cli.md and the
    # help write MATCHES.csv
    code, _, err = cli("orient", "relative", points, *ARGS, "--report", points)
    assert code == 2
    assert f"--report {points} is the input file MATCHES" in err
    code, _, err = cli("orient", "relative", *ARGS)
    assert code == 2
    assert "Usage: photogeom orient relative [OPTIONS] {matches} [image2]" in err
    assert "Missing argument 'matches'" in " ".join(err.split())
    cli_md = (Path(__file__).parents[1] / "docs" / "cli.md").read_text(encoding="utf-8")
    assert "## `photogeom orient relative MATCHES.csv [IMAGE2.csv]`" in cli_md
