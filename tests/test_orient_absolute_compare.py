"""``orient absolute --compare`` exited 0 when a method failed: it runs every
method, as a batch command runs its items, so a failed method now ends the command with
``error: K of N methods failed ...`` and exit code 1 (docs/cli.md), after the table, the
JSON and the report."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets


@pytest.fixture
def nearly_collinear(tmp_path: Path) -> Path:
    """Four points 0.1 mm off a 300 m line: the closed form refuses them, the others solve."""
    rng = np.random.default_rng(1)
    x = np.array([[0, 0, 0], [1, 0, 0], [2, 1e-3, 0.0], [3, 0, 1e-3]]) * 100
    X = 2 * x + np.array([10.0, 20.0, 30.0]) + rng.normal(size=x.shape) * 1e-6
    lines = ["id,x,y,z,X,Y,Z"]
    for k, (a, b) in enumerate(zip(x.tolist(), X.tolist()), start=1):
        lines.append(",".join([str(k), *map(repr, a), *map(repr, b)]))
    f = tmp_path / "pairs.csv"
    f.write_text("\n".join(lines) + "\n")
    return f


def test_a_failed_method_exits_1_after_the_table(cli, nearly_collinear: Path):
    code, out, err = cli("orient", "absolute", nearly_collinear, "--compare")
    assert code == 1
    assert "closed-form: failed:" in out and "gauss-markov" in out
    assert "error: 1 of 6 methods failed: closed-form" in err


def test_json_and_report_are_written_before(cli, nearly_collinear: Path, tmp_path: Path):
    import json

    report = tmp_path / "cmp.html"
    code, out, err = cli("orient", "absolute", nearly_collinear, "--compare", "--json",
                         "--report", report)
    assert code == 1
    assert json.loads(out)["methods"]
    assert report.is_file()
    assert "1 of 6 methods failed" in err and "see the report" in err


def test_all_methods_solving_still_exits_0(cli):
    code, _, err = cli("orient", "absolute", datasets.path("kraus_absolute_orientation"),
                       "--compare")
    assert code == 0, err
