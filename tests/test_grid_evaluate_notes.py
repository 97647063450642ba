"""``photogeom grid evaluate`` prints the re-adjustment's notes and puts them in --json.

Before, the notes of the re-adjustment (``BundleFit.notes``: why sigma0 is over the chain's
effective redundancy or over the re-adjustment's own, that the standard deviations are
in-sample) were dropped: the table showed "(effective)" or a plain redundancy without the
why. They are now printed as ``note: ...`` lines and listed under ``notes`` of --json, in the
command's words (its options and BLOCK, not Python names).
"""

from __future__ import annotations

import json
import re
import types
from pathlib import Path

import pytest

from photogeom import datasets
from photogeom.calibration.blocks import IN_SAMPLE_NOTE, NO_CHAIN_NOTE, NOT_ITS_GRIDS_NOTE
from photogeom.calibration.chain import _first_words
from photogeom.calibration.in_adjustment import IN_ADJUSTMENT_NOTE
from photogeom.cli.grid_block import note_words

#: Python names a note of the command line must not show.
PYTHON = re.compile(
    r"GridAdjustment|effective_redundancy|adjust_with_grids|fit_residual_grids|"
    r"(?<![\w-])readjust\b|bundle_adjust|\w+=|\w\(\)"
)


def _printed(text: str) -> list[str]:
    """The ``note: ...`` lines of the printed output."""
    return [s[len("note: ") :] for s in text.splitlines() if s.startswith("note: ")]


def test_preset_prints_the_in_sample_note(cli):
    args = ("grid", "evaluate", "--preset", "FC300S", "--strips", "1", "--images", "3",
            "--spacing", "500")  # fmt: skip
    code, text, err = cli(*args)
    assert code == 0, err
    notes = _printed(text)
    # the grids are fitted to the first adjustment's residuals: the library's note says so
    assert len(notes) == 1
    assert notes[0].startswith(IN_SAMPLE_NOTE.split(" (first adjustment")[0])
    assert "the redundancy marked effective" in notes[0]
    assert "--rematch for a --preset block" in notes[0]
    assert not PYTHON.search(notes[0]), notes[0]


def test_a_block_not_adjusted_says_why_sigma0_is_plain(cli):
    # the bundled 3-image BAL block before adjustment: no first adjustment to linearise
    bal = Path(datasets.__file__).parent / "data" / "bundle" / "dubrovnik-3-7-pre.txt"
    args = ("grid", "evaluate", bal, "--spacing", "500")
    code, text, err = cli(*args, "--json")
    assert code == 0, err
    (note,) = json.loads(text)["notes"]
    code, text, err = cli(*args)
    assert code == 0, err
    assert _printed(text) == [note]  # printed as in --json
    assert note.startswith(NO_CHAIN_NOTE.split(" (adjust the block first")[0])
    assert "(adjust BLOCK first, 'photogeom bundle adjust BLOCK -o ADJUSTED'" in note
    assert "not positive definite" in note  # the reason, as the library gives it
    assert not PYTHON.search(note), note


@pytest.mark.parametrize(
    "note",
    [
        IN_SAMPLE_NOTE,
        NO_CHAIN_NOTE + ": normal matrix of the first adjustment is not positive definite",
        NOT_ITS_GRIDS_NOTE,
        IN_ADJUSTMENT_NOTE,
        _first_words(types.SimpleNamespace(lost="the observations", joint=False))["note"],
    ],
)
def test_every_note_of_the_readjustment_reads_in_command_words(note):
    # the library's notes name Python; each phrase has its command-line words (a library
    # text changed without them fails here)
    (cli_note,) = note_words([note])
    assert not PYTHON.search(cli_note), cli_note
    if PYTHON.search(note):
        assert cli_note != note
