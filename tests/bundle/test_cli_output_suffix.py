"""The format of a block written by `bundle adjust -o` and `bundle convert`: the output's
name chooses it the same way in both (.bal, .txt, .bz2: BAL; .out: Bundler; any other
name: the input's format for `adjust`), and a suffix that says another format than an
explicit --output-format / --to is refused before anything is computed."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

import photogeom.bundle as bundle
from photogeom import MetashapeCalibration
from photogeom.bundle import write_csv_block

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block

#: a camera BAL and Bundler hold exactly (f, k1, k2), adjusted with --free f,k1,k2
CAL = MetashapeCalibration(3000, 2000, 2400.0, k1=-0.08, k2=0.03)
ADJUST = ["--free", "f,k1,k2", "--drop-extras", "--no-snooping"]


@pytest.fixture(scope="module")
def block_dir(tmp_path_factory):
    """A small CSV block with control points, written by the library."""
    d = tmp_path_factory.mktemp("src") / "grid"
    write_csv_block(grid_block(2, rows=2, cols=3, n_points=120, noise=0.3, cal=CAL), d)
    return d


def _tree(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


@pytest.mark.parametrize(
    ("name", "reader"),
    [("new.bal", bundle.read_bal), ("new.out", bundle.read_bundler)],
)
def test_adjust_output_format_follows_the_suffix(block_dir, cli, tmp_path, name, reader):
    # before: a CSV folder named new.bal (new.out) was written, as the input's format
    out = tmp_path / name
    code, _, err = cli("bundle", "adjust", block_dir, "-o", out, *ADJUST)
    assert code == 0, err
    assert out.is_file(), _tree(tmp_path)
    back = reader(out, image_size=(3000, 2000)) if name.endswith(".out") else reader(out)
    csv = bundle.read_csv_block(block_dir)
    assert back.n_images == csv.n_images and back.n_points == csv.n_points
    assert back.n_observations == csv.n_observations


def test_adjust_output_folder_keeps_the_input_format(block_dir, cli, tmp_path):
    out = tmp_path / "adjusted"
    code, _, err = cli("bundle", "adjust", block_dir, "-o", out, *ADJUST)
    assert code == 0, err
    assert (out / "images.csv").is_file()


@pytest.mark.parametrize(
    ("command", "option", "name", "fmt"),
    [
        ("adjust", "--output-format", "new.bal", "csv"),
        ("adjust", "--output-format", "new.out", "bal"),
        ("adjust", "--output-format", "new.bz2", "colmap"),
        ("convert", "--to", "new.bal", "colmap-bin"),
        ("convert", "--to", "new.out", "csv"),
        ("convert", "--to", "new.txt", "bundler"),
    ],
)
def test_a_suffix_contradicting_the_format_is_refused(
    block_dir, cli, tmp_path, monkeypatch, command, option, name, fmt
):
    def refuse(*a, **k):  # pragma: no cover - reached only when the check comes too late
        raise AssertionError("computed before the output was checked")

    monkeypatch.setattr(bundle, "bundle_adjust", refuse)
    out = tmp_path / "o" / name
    out.parent.mkdir()
    args = ["-o", out] if command == "adjust" else [out]
    code, _, err = cli("bundle", command, block_dir, *args, option, fmt)
    assert code == 2, err
    assert err.startswith(f"error: {option} {fmt} contradicts the name {out}"), err
    assert "Traceback" not in err
    assert _tree(tmp_path / "o") == []


def test_an_agreeing_explicit_format_is_accepted(block_dir, cli, tmp_path):
    out = tmp_path / "x.bal"
    code, _, err = cli("bundle", "convert", block_dir, out, "--to", "bal", "--drop-extras")
    assert code == 0, err
    assert bundle.read_bal(out).n_images == bundle.read_csv_block(block_dir).n_images
