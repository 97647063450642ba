"""`bundle adjust/convert --sigma` out of range named the first row of the block
that lacks a sigma column ("observations.csv, line 3: sigma must be positive") instead of
the option the user gave."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def block_without_sigmas(tmp_path_factory) -> Path:
    from photogeom.cli.main import main

    root = tmp_path_factory.mktemp("b") / "block"
    try:
        main(["bundle", "simulate", str(root), "--strips", "2", "--images-per-strip", "3",
              "--json"])
    except SystemExit as exc:  # pragma: no cover - the simulation works
        assert not exc.code
    obs = root / "observations.csv"
    lines = obs.read_text().splitlines()
    obs.write_text("\n".join(ln if ln.startswith("#") else ",".join(ln.split(",")[:4])
                             for ln in lines) + "\n")
    return root


@pytest.mark.parametrize("sigma", ["-1", "0", "nan"])
@pytest.mark.parametrize("command", ["adjust", "convert"])
def test_bad_sigma_names_the_option(cli, tmp_path: Path, block_without_sigmas, sigma, command):
    extra = [tmp_path / "out", "--to", "csv"] if command == "convert" else []
    code, _, err = cli("bundle", command, block_without_sigmas, *extra, "--sigma", sigma)
    assert code == 2
    assert err.startswith(f"error: --sigma {sigma}:") and "line" not in err
