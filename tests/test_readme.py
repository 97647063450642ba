"""The Python examples of README.md run as written (in a temporary directory)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def _python_blocks() -> list[str]:
    text = README.read_text(encoding="utf-8")
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


@pytest.mark.skipif(not README.is_file(), reason="README.md is not beside the tests")
def test_readme_python_examples_run(tmp_path, monkeypatch):
    blocks = _python_blocks()
    assert len(blocks) >= 2
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for block in blocks:  # later blocks use names of earlier ones, as a reader would
        exec(compile(block, str(README), "exec"), namespace)
    fit = namespace["fit"]
    assert fit.params["a"] == pytest.approx(1.0000354, abs=5e-8)
    xy = namespace["xy"]
    assert xy[0] == pytest.approx(22.7354, abs=5e-5) and xy[1] == pytest.approx(-32.7917, abs=5e-5)
    assert (tmp_path / "io-report.html").is_file()
    assert len(namespace["bal"].image_ids) == 3  # dubrovnik-3-7
    assert (tmp_path / "dubrovnik.bal").is_file()
    assert len(namespace["model"].image_ids) == 21  # the FC300S block, via COLMAP text
    assert namespace["binary_model"].image_ids.tolist() == namespace["model"].image_ids.tolist()
    assert namespace["pt"].role in {"tie", "control", "check"}


# The names of the specification's "Public API contract" sections (the overview, residual
# grids, bundle adjustment with the simulator and relative orientation), as they are called.
SPEC_CONTRACT = (
    "pg.opk_matrix(",
    "pg.opk_from_matrix(",
    "pg.absolute_orientation(",
    ".scale",
    ".rotation",
    ".translation",
    ".residuals",
    ".sigma0",
    ".std_errors",
    ".transform.apply(",
    "pg.simulate.uav_block(",
    ".local_field(",
    "pg.bundle_adjust(",
    ".block",
    ".truth",
    ".redundancy",
    ".converged",
    ".iterations",
    "pg.bundle.read_bal(",
    "pg.bundle.write_bal(",
    "pg.bundle.read_colmap(",
    "pg.bundle.write_colmap(",
    ".cameras[",
    ".images[",
    ".camera",
    ".exterior",
    ".points[",
    ".xyz",
    ".role",
    ".observations",
    ".image_ids",
    ".point_ids",
    ".uv",
    ".sigma",
    "pg.bundle.reprojection_residuals(",
    "pg.calibration.fit_residual_grids(",
    ".evaluate(",
    "pg.calibration.correct_observations(",
    "pg.calibration.readjust(",
    "pg.calibration.model_steps(",
    "pg.relative_orientation(",
    ".exterior1",
    ".exterior2",
    ".parallax",
)


@pytest.mark.skipif(not README.is_file(), reason="README.md is not beside the tests")
def test_readme_contract_names_the_spec_contract():
    # the README's contract lacked pg.bundle.read_bal / write_bal / read_colmap /
    # write_colmap, block.points[...] (.xyz, .role), block.observations (.image_ids,
    # .point_ids, .uv, .sigma) and sim.truth, all names of the specification's contract
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Public API contract") :]
    contract = _python_blocks_of(section)[0]
    missing = [name for name in SPEC_CONTRACT if name not in contract]
    assert not missing, missing


def _python_blocks_of(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)
