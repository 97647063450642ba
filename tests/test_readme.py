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
