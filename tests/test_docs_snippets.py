"""Every Python snippet of README.md and docs/*.md is Python, and calls names that exist.

Most snippets of docs/*.md use the reader's own data (``source``, ``target``, a block), so
they cannot all run here (the README's and a few pages' do, in other tests). They can all be
parsed, and every dotted ``pg.`` / ``photogeom.`` name they use can be looked up: a snippet
that a reader copies stops neither at a syntax error nor at a renamed function. Fast: no
snippet is executed.
"""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

pytestmark = pytest.mark.skipif(
    not (ROOT / "docs").is_dir(), reason="docs/ is not beside the tests"
)


def python_blocks(page: Path) -> list[tuple[int, str]]:
    """``(first line, code)`` of every fenced ``python`` block of ``page``."""
    out, code, start = [], None, 0
    for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        if line.startswith("```"):
            if code is None and line[3:].strip() == "python":
                code, start = [], number + 1
            elif code is not None:
                out.append((start, "\n".join(code)))
                code = None
        elif code is not None:
            code.append(line)
    return out


def test_every_python_snippet_parses():
    # relative-orientation.md and residual-grid.md wrote their placeholders as
    # {"101": io, ...} and {"DSC01234": (uv, residuals), ...}: SyntaxError on the block's
    # first statement, before anything ran
    problems = []
    for page in PAGES:
        for start, code in python_blocks(page):
            try:
                ast.parse(code)
            except SyntaxError as exc:
                problems.append(f"{page.name}:{start + (exc.lineno or 1) - 1}: {exc.msg}")
    assert not problems, problems


def _lookup(dotted: str) -> str | None:
    """None when ``photogeom.<dotted>`` exists (attribute or submodule), else the first
    part that does not."""
    import photogeom

    obj, where = photogeom, "photogeom"
    for part in dotted.split("."):
        nxt = getattr(obj, part, None)
        if nxt is None and hasattr(obj, "__path__"):
            try:
                nxt = importlib.import_module(f"{obj.__name__}.{part}")
            except ImportError:
                nxt = None
        if nxt is None:
            return f"{where}.{part}"
        obj, where = nxt, f"{where}.{part}"
    return None


def test_every_photogeom_name_of_the_snippets_exists():
    problems = set()
    for page in PAGES:
        for _, code in python_blocks(page):
            for m in re.finditer(r"\b(?:pg|photogeom)((?:\.[A-Za-z_]\w*)+)", code):
                missing = _lookup(m.group(1).lstrip("."))
                if missing:
                    problems.add(f"{page.name}: {m.group(0)} ({missing} does not exist)")
    assert not problems, sorted(problems)


def test_pages_speak_of_the_product_not_of_its_development_rounds():
    # seven passages dated a change by the number of a development round, which a reader
    # of the product's documentation cannot look up (file names of tests, which a reader
    # can open, are allowed)
    problems = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"(?<![\w/])review \d+\w?", text, flags=re.I):
            line = text.count("\n", 0, m.start()) + 1
            problems.append(f"{page.name}:{line}: {m.group(0)}")
    assert not problems, problems


def test_residual_grid_page_node_counts_are_the_layouts():
    # the page said "a 42 Mpx image at 100 px has 4 300" nodes beside MAX_NODES, where a
    # 7952 x 5304 px image at 100 px has 55 x 81 = 4455 (as the README and the page's own
    # speed table say, and as grid fit prints: "nodes 55x81")
    from photogeom.calibration.grid import MAX_NODES, GridLayout

    text = (ROOT / "docs" / "residual-grid.md").read_text(encoding="utf-8")
    layout = GridLayout(7952, 5304, 100)
    ny, nx = layout.shape
    assert (ny, nx) == (55, 81)
    assert "a 7952 x 5304 image at 100 px has 55 x 81 nodes" in text
    m = re.search(r"at most ([\d,]+) nodes[^)]*?has (\d+) x (\d+) = ([\d ]+)\)", text)
    assert m, "the MAX_NODES sentence"
    assert int(m.group(1).replace(",", "")) == MAX_NODES
    assert (int(m.group(2)), int(m.group(3))) == (ny, nx)
    assert int(m.group(4).replace(" ", "")) == layout.n_nodes


def test_bundle_page_undetectable_blunder_block_is_the_one_named():
    # the page named uav_block("FC300S", seed=3) for "a 20 px (40 sigma) error ... gave |w|
    # 2.5 and was not flagged"; on that block (0.3 px noise) the same error gives |w| 3.8 and
    # is flagged: the numbers are those of the block with 0.5 px noise and no local field
    import numpy as np

    import photogeom as pg

    text = (ROOT / "docs" / "bundle-adjustment.md").read_text(encoding="utf-8")
    m = re.search(r"`(uav_block\([^`]*\))` \(0\.5 px\s+noise, no local field\) (\d+) image", text)
    assert m, "the block of the undetectable blunder"
    call = ast.parse(m.group(1), mode="eval").body  # the page's own call, literals only
    args = [ast.literal_eval(a) for a in call.args]
    kwargs = {k.arg: ast.literal_eval(k.value) for k in call.keywords}
    sim = pg.simulate.uav_block(*args, **kwargs)
    fit = pg.bundle_adjust(sim.block)
    assert len(fit.snooping["poorly_controlled"]) == int(m.group(2))
    red = fit.snooping["redundancy_numbers"]
    k = int(np.flatnonzero(np.nan_to_num(red[:, 0], nan=1.0) < 0.01)[0])
    sigma = float(sim.block.observations.sigma[k])
    assert 20.0 / sigma == pytest.approx(40.0)  # "20 px (40 sigma)"
    uv = sim.block.observations.uv.copy()
    uv[k, 0] += 20.0
    bad = pg.bundle_adjust(sim.block.with_observations(uv=uv))
    w = float(np.max(np.abs(bad.snooping["w"][k])))
    assert round(w, 1) == 2.5 and w < bad.snooping["critical_value"]


def test_simulation_page_preset_table_is_the_presets():
    # the table gave the FC300S flying height as 56.3 m, a rounding of 56.25 m that the
    # simulator's summary prints as 56.2 m: the table's numbers are the presets' to the
    # digits shown, and no rounding of a half
    import photogeom as pg

    text = (ROOT / "docs" / "simulation.md").read_text(encoding="utf-8")
    checked = 0
    for name, preset in pg.simulate.PRESETS.items():
        row = next(line for line in text.splitlines() if line.startswith(f'| `"{name}"` | '))
        cells = [c.strip() for c in row.split("|")[1:-1]]
        f_px, gsd, height = cells[4], cells[5], cells[6]
        assert float(f_px) == pytest.approx(preset.focal_px, abs=0.05)
        assert float(gsd.split()[0]) / 100 == pytest.approx(preset.gsd)
        shown = height.split()[0]
        digits = len(shown.split(".")[1]) if "." in shown else 0
        value = preset.flying_height(preset.gsd)
        assert float(shown) == round(value, digits), (name, shown, value)
        assert f"{value:.{digits}f}" == shown, (name, shown, value)  # as Python prints it
        checked += 1
    assert checked == 3
