"""The option tables of the documentation name what the commands take.

docs/cli.md and docs/bundle-adjustment.md give tables of options; a test beside this one
checks that every option they list exists. These check the other direction: what a command
accepts is in its table.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"

pytestmark = pytest.mark.skipif(not DOCS.is_dir(), reason="docs/ is not beside the tests")


def _table_row(page: str, option: str) -> str:
    """The one table row of ``docs/page`` whose first cell starts with ``option``."""
    rows = [
        line
        for line in (DOCS / page).read_text(encoding="utf-8").splitlines()
        if line.startswith(f"| `{option} ") or line.startswith(f"| `{option}`")
    ]
    assert len(rows) == 1, f"{page}: {len(rows)} table rows for {option}"
    return rows[0]


def test_output_calibration_row_names_every_suffix():
    # the table and synopsis of bundle adjust listed .xml, .json and .yaml, while
    # --output-calibration cal.txt writes a COLMAP cameras.txt (as its --help says)
    from photogeom.camera.calibration_files import CALIBRATION_SUFFIXES

    row = _table_row("bundle-adjustment.md", "--output-calibration")
    first, meaning = re.split(r"(?<!\\)\|", row)[1:3]
    text = (DOCS / "bundle-adjustment.md").read_text(encoding="utf-8")
    synopsis = re.search(r"\[--output-calibration ([^\]]+)\]", text).group(1)
    for suffix in CALIBRATION_SUFFIXES:
        assert f"`{suffix}`" in meaning, f"{suffix} is not described"
        if suffix != ".yml":  # the short form of .yaml, described beside it
            assert suffix in first.replace("\\", ""), f"{suffix} not in {first}"
            assert suffix in synopsis, f"{suffix} not in the synopsis {synopsis}"
