"""docs/bundle-adjustment.md states the defaults and the backends that BundleOptions has."""

from __future__ import annotations

import re
from pathlib import Path

from photogeom.adjust.sparse import BACKENDS
from photogeom.bundle import BundleOptions

DOC = Path(__file__).parents[2] / "docs" / "bundle-adjustment.md"


def _row(text: str, first_cell: str) -> list[str]:
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells and cells[0] == first_cell:
            return cells
    raise AssertionError(f"no options-table row {first_cell}")


def test_convergence_defaults_are_the_code_defaults():
    text = DOC.read_text()
    o = BundleOptions()
    defaults = _row(text, "`max_iterations`, `ftol`, `xtol`")[1]
    assert [float(v) for v in defaults.split(",")] == [o.max_iterations, o.ftol, o.xtol]
    assert f"`ftol` ({o.ftol:g}) times the cost" in text
    assert f"`xtol` ({o.xtol:g})" in text


def test_every_backend_the_code_accepts_is_documented():
    row = _row(DOC.read_text(), "`backend`")
    assert row[1] == f'`"{BundleOptions().backend}"`'
    named = set(re.findall(r'`"(\w+)"`', row[2]))
    assert named == set(BACKENDS)
