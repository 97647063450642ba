"""The report of 'transform estimate --allow-unmatched' names the points left out as the
text output does: the first 20 per file and how many there are in all."""

from __future__ import annotations

import html
import re

import numpy as np


def _files(tmp_path, n_source_only: int, n_target_only: int):
    rng = np.random.default_rng(4)
    x = rng.uniform(0, 1000, (10 + n_source_only, 2))
    s, t = tmp_path / "s.csv", tmp_path / "t.csv"
    s.write_text("id,x,y\n" + "".join(f"p{i},{a:.4f},{b:.4f}\n" for i, (a, b) in enumerate(x)))
    rows = [f"p{i},{a + 100:.4f},{b + 5:.4f}\n" for i, (a, b) in enumerate(x[:10])]
    rows += [f"q{i},1.0,2.0\n" for i in range(n_target_only)]
    t.write_text("id,X,Y\n" + "".join(rows))
    return s, t


def _left_out(path) -> str:
    """The paragraph of the report's Input section on the points left out."""
    text = path.read_text(encoding="utf-8")
    return html.unescape(re.search(r"<p>(Left out \(no partner.*?)</p>", text).group(1))


def test_many_unmatched_ids_are_counted_not_all_listed(cli, tmp_path):
    # before: every id of both files in one paragraph (4980 ids for 2980 and 2000 left out),
    # and no count
    s, t = _files(tmp_path, 60, 30)
    rep = tmp_path / "r.html"
    code, _, err = cli("transform", "estimate", "similarity2d", s, t, "--allow-unmatched",
                       "--report", rep)  # fmt: skip
    assert code == 0, err
    line = _left_out(rep)
    shown_p = re.findall(r"\bp\d+\b", line)
    shown_q = re.findall(r"\bq\d+\b", line)
    assert shown_p == [f"p{i}" for i in range(10, 30)]  # the first 20 source-only ids
    assert shown_q == [f"q{i}" for i in range(20)]
    assert "(60 in all)" in line and "(30 in all)" in line
    assert "all in --json" in line


def test_few_unmatched_ids_are_all_listed(cli, tmp_path):
    s, t = _files(tmp_path, 3, 2)
    rep = tmp_path / "r.html"
    code, _, err = cli("transform", "estimate", "similarity2d", s, t, "--allow-unmatched",
                       "--report", rep)  # fmt: skip
    assert code == 0, err
    line = _left_out(rep)
    assert line.endswith("source only p10, p11, p12; target only q0, q1.")
