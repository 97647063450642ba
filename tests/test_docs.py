"""Snippets of docs/*.md run as written (the documentation, executed).

Each test takes a documented code block by a line it contains, runs it in a temporary
directory with the names the surrounding page defines before it, and checks what the page
says it gives.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg

DOCS = Path(__file__).resolve().parents[1] / "docs"

pytestmark = pytest.mark.skipif(not DOCS.is_dir(), reason="docs/ is not beside the tests")


def doc_block(page: str, containing: str) -> str:
    """The python block of ``docs/page`` that contains ``containing`` (exactly one)."""
    text = (DOCS / page).read_text(encoding="utf-8")
    blocks = [b for b in re.findall(r"```python\n(.*?)```", text, flags=re.S) if containing in b]
    assert len(blocks) == 1, f"{page}: {len(blocks)} python blocks contain {containing!r}"
    return blocks[0]


def run_block(block: str, namespace: dict, where: str) -> dict:
    exec(compile(block, where, "exec"), namespace)
    return namespace


def test_residual_grid_in_adjustment_snippet_node_std(tmp_path, monkeypatch):
    # The documented snippet ended in ga.node_std[image_id], which raised TypeError
    # ('NoneType' object is not subscriptable) on its own 500 px grids: node_std is None
    # above the limit of unknowns after the points (then 5000) unless std=True.
    monkeypatch.chdir(tmp_path)
    # the case of the page's own block: more unknowns than the default limit of the dense
    # node covariance (here by lowering the limit, to keep the test small)
    from photogeom.calibration import in_adjustment

    monkeypatch.setattr(in_adjustment, "STD_MAX", 0)
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=3)
    res = pg.bundle_adjust(sim.block)
    block = doc_block("residual-grid.md", "adjust_with_grids(res.block, 500")
    ns = run_block(block, {"pg": pg, "res": res}, "residual-grid.md")
    ga, image_id, uv = ns["ga"], ns["image_id"], ns["uv"]
    assert ga.grids[image_id].evaluate(uv).shape == (5, 2)
    assert ga.node_std is None
    text = (DOCS / "residual-grid.md").read_text(encoding="utf-8")
    assert "ga.node_std[image_id]" not in text


@pytest.mark.slow
def test_residual_grid_node_std_limit_as_documented():
    # the page: on the 21-image ILCE-7RM2 block 1000 px grids give node standard deviations
    # of shape (ny, nx, 2) = (7, 9, 2) by default, and so do 500 px grids (8700 unknowns
    # after the points; None while the limit was 5000, when one triangular solve per node
    # took 31.5 s there, now 4.7 s)
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1)
    res = pg.bundle_adjust(sim.block)
    opts = {"sigma_constraint": 1.0, "sigma_temporal": 0.3}
    coarse = pg.calibration.adjust_with_grids(res.block, 1000, **opts)
    first = res.block.image_ids[0]
    assert coarse.node_std is not None and coarse.node_std[first].shape == (7, 9, 2)
    fine = pg.calibration.adjust_with_grids(res.block, 500, **opts)
    assert 5000 < fine.n_unknowns - 3 * res.block.n_points <= 10000
    assert fine.node_std is not None and fine.node_std[first].shape == (12, 17, 2)
    assert np.all(fine.node_std[first] > 0)
    assert np.isfinite(fine.grids[first].nodes).all()


def _cli_params() -> dict:
    """``{"group command": {option name: click parameter}}`` of the whole command line."""
    import typer

    from photogeom.cli.main import app

    out: dict = {}

    def walk(cmd, path):
        if hasattr(cmd, "list_commands"):
            ctx = cmd.context_class(cmd)  # the click of the command itself (typer vendors one)
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), [*path, name])
        else:
            out[" ".join(path)] = {o: p for p in cmd.params for o in (*p.opts, *p.secondary_opts)}

    walk(typer.main.get_command(app), [])
    return out


def _choices(param) -> set:
    """The values a choice option takes (an Enum annotation of typer, or click's Choice)."""
    import enum

    ann = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    if isinstance(ann, type) and issubclass(ann, enum.Enum):
        return {str(e.value) for e in ann}
    return set(getattr(getattr(param, "type", None), "choices", ()) or ())


def test_cli_md_option_tables_match_the_commands():
    # docs/cli.md listed --angle-unit deg|gon|rad for orient relative, which also takes
    # arcsec; every option of a command's table must exist and list the command's choices
    params = _cli_params()
    section = None
    problems = []
    for line in (DOCS / "cli.md").read_text(encoding="utf-8").splitlines():
        m = re.match(r"#+ `photogeom ([a-z-]+) ([a-z-]+)", line)
        if line.startswith("#"):
            section = f"{m.group(1)} {m.group(2)}" if m else None
            continue
        if section not in params or not line.startswith("| `"):
            continue
        first = re.split(r"(?<!\\)\|", line)[1]  # cells split at unescaped bars
        for opt, choices in re.findall(r"`(--[a-z][\w-]*)(?: ([\w\\|-]+\|[\w\\|-]+))?", first):
            p = params[section].get(opt)
            if p is None:
                problems.append(f"{section}: {opt} is not an option")
            elif choices:
                listed = set(choices.replace("\\", "").split("|"))
                actual = _choices(p)
                if actual and listed != actual:
                    problems.append(f"{section}: {opt} lists {sorted(listed)} of {sorted(actual)}")
    assert not problems, problems
