"""`grid evaluate` and `grid sweep` on a block without consecutive stereo models.

The bundled ``dubrovnik-3-7-pre.txt`` (3 images, no strip of overlapping models) has
residuals to compare but no height step. ``grid evaluate --json`` ended in a traceback
("Out of range float values are not JSON compliant: nan") and the table printed
``nan %``; ``grid sweep`` said ``sweep_spacings: ...`` in the library's words.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from photogeom import datasets

BAL = Path(datasets.__file__).parent / "data" / "bundle" / "dubrovnik-3-7-pre.txt"


def test_evaluate_json_gives_null_steps_and_the_residuals(cli):
    code, text, err = cli("grid", "evaluate", BAL, "--spacing", "500", "--json")
    assert code == 0, err
    d = json.loads(text)  # strict JSON: no NaN
    assert d["steps_before"] == {} and d["steps_after"] == {}
    assert d["mean_step_before"] is None and d["step_reduction"] is None
    blk = d["residuals"]["block"]
    assert np.isfinite(blk["before"]["rms"]) and blk["after"]["rms"] < blk["before"]["rms"]


def test_evaluate_table_says_there_are_no_steps(cli):
    code, text, err = cli("grid", "evaluate", BAL, "--spacing", "500")
    assert code == 0, err
    out = text + err
    assert "no pair of consecutive stereo models" in out and "--overlap 0.6" in out
    assert "nan" not in out.lower()
    assert "mean length" in out


def test_sweep_refuses_in_the_words_of_the_command(cli):
    code, _text, err = cli("grid", "sweep", BAL)
    assert code != 0
    assert "no pair of consecutive stereo models" in err
    assert "--overlap" in err and "grid evaluate" in err
    assert "sweep_spacings" not in err and "Traceback" not in err
