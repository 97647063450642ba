"""The summary that ``photogeom bundle adjust`` prints points to the options, not to Python.

Before, it sent the user to ``snooping['flagged'] of the result`` and
``snooping['poorly_controlled']`` and to "no free parameters" / "the free parameters", the
words of ``pg.bundle_adjust``; the command line has ``--json``, ``--result``, ``--report`` and
``--free`` for them.
"""

from __future__ import annotations

import json
import re


def test_printed_summary_names_options_not_python_keys(cli, tmp_path):
    # the README's block: two blunders, k2 / k3 correlated, points seen in two images
    code, _, err = cli("bundle", "simulate", tmp_path / "uav", "--seed", "1", "--blunders", "2")
    assert code == 0, err
    code, out, err = cli("bundle", "adjust", tmp_path / "uav", "--result", tmp_path / "r.json")
    assert code == 0, err
    # the four pointers are printed (the block has all of them) ...
    assert "more with smaller |w| (all of them in the JSON of --json and --result: " in out
    assert "snooping.flagged)" in out
    assert "listed in --report and in the JSON of --json and --result" in out
    assert "(snooping.poorly_controlled)" in out
    assert "(leave it out of --free)" in out
    assert "held first (--free none -o FIRST)" in out
    # ... with no Python subscripts, keywords or function names
    assert not re.search(r"\w\[['\"]", out), out
    assert "photogeom." not in out and "free parameters" not in out
    # the keys named are those of the record written, and hold every observation counted
    rec = json.loads((tmp_path / "r.json").read_text())
    flagged = int(re.search(r"(\d+) observation\(s\) flagged", out).group(1))
    poor = int(re.search(r"note: (\d+) image observation\(s\) are poorly", out).group(1))
    assert len(rec["snooping"]["flagged"]) == flagged > 20
    assert len(rec["snooping"]["poorly_controlled"]) == poor > 0


def test_library_summary_names_no_command_line_options(cli, tmp_path):
    """The other way round: ``BundleFit.summary`` (Python) pointed to ``--json``."""
    import photogeom as pg

    code, _, err = cli("bundle", "simulate", tmp_path / "uav", "--seed", "1", "--blunders", "2")
    assert code == 0, err
    text = pg.bundle_adjust(pg.bundle.read_block(tmp_path / "uav")).summary()
    assert "snooping['flagged'] of the result" in text
    # options only where the text says they are the command line's
    python_words = re.sub(r"on the command line [^)]*", "", text)
    assert not re.search(r"(?<![\w-])--[a-z]", python_words), text
