"""`photogeom bundle adjust --alpha`: the significance level of the w-test per observation
(``BundleOptions.alpha``), an option of the command."""

from __future__ import annotations

import json

import pytest


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    from photogeom.cli.main import main

    path = tmp_path_factory.mktemp("alpha") / "blk"
    try:
        main(["bundle", "simulate", str(path), "--strips", "2", "--images-per-strip", "4",
              "--blunders", "3", "--tie-points-per-image", "40"])  # fmt: skip
    except SystemExit as exc:
        assert not exc.code
    return path


def test_alpha_sets_the_level_of_the_tests(cli, block, tmp_path):
    code, out, err = cli("bundle", "adjust", block, "--json")
    assert code == 0, err
    default = json.loads(out)["snooping"]
    assert default["alpha"] == 0.001
    result = tmp_path / "r.json"
    code, out, err = cli("bundle", "adjust", block, "--json", "--alpha", "0.05", "--result", result)
    assert code == 0, err
    sn = json.loads(out)["snooping"]
    assert sn["alpha"] == 0.05
    assert sn["critical_value"] == pytest.approx(1.95996, abs=1e-5)
    assert len(sn["flagged"]) > len(default["flagged"])
    assert json.loads(result.read_text())["snooping"]["alpha"] == 0.05
    code, out, err = cli("bundle", "adjust", block, "--alpha", "0.05")
    assert code == 0, err
    assert "alpha 0.05, critical 1.96" in out


@pytest.mark.parametrize("value", ["0", "0.5", "nan"])
def test_alpha_out_of_range_is_refused_by_its_name(cli, block, value):
    code, _, err = cli("bundle", "adjust", block, "--alpha", value)
    assert code == 2
    assert f"--alpha must be in (0, 0.5), got {float(value)}" in err
