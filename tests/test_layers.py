"""The package's layers, as the README's "Development" section describes them.

A module imports from its own layer and the layers above it; the few imports that reach
into a lower layer are the shared helpers the README names (the bounded reading of files
and pipes and the atomic writes of ``io``, the number formatting of ``report.format``,
``bundle``'s COLMAP text, ``io.cloud`` for ``distributed``). Any other such import is
reported: either the README is told, or the code moves.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "photogeom"

pytestmark = pytest.mark.skipif(not SRC.is_dir(), reason="src/photogeom is not beside the tests")

LAYERS = (
    # the base: errors, checks and records, units, rotations, image coordinates, CRSs, the
    # machine
    ("errors", "validation", "records", "numbers", "units", "rotation", "imagecoords",
     "xmlsafe", "atomicfile", "_pipe_scope", "crs", "machine"),
    ("transforms",),
    ("adjust",),
    ("estimation", "orientation", "camera", "rpc"),
    ("bundle", "simulate", "calibration", "distributed"),
    ("io", "report", "cli", "datasets", "examples"),
)  # fmt: skip

#: io's helpers that the file readers and writers below it share: bounded reading of files
#: and pipes, JSON limits, CSV text, atomic writes.
IO_HELPERS = {"io.sources", "io.jsonfile", "io.atomic", "io.csvblocks"}
READERS = {"camera", "rpc", "bundle", "calibration"}

#: Other ``(importing package, imported module)`` pairs that reach into a lower layer.
SHARED = {
    ("adjust", "report.format"),  # number formatting of Fit.summary
    ("orientation", "report.format"),  # and of the method comparison
    ("camera", "bundle.io_colmap"),  # COLMAP cameras.txt calibration files
    ("camera", "bundle._textio"),
    ("distributed", "io.cloud"),  # register_clouds reads LAS/LAZ
}


def _layer() -> dict[str, int]:
    return {name: i for i, names in enumerate(LAYERS) for name in names}


def downward_imports() -> dict[tuple[str, str], list[str]]:
    """``{(package, imported module): [files]}`` of every import into a lower layer,
    module level or inside a function."""
    layer = _layer()
    out: dict[tuple[str, str], list[str]] = {}
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC)
        package = rel.parts[0].removesuffix(".py")
        if package not in layer:
            continue
        parts = list(rel.parts[:-1])
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level:
                if node.level - 1 > len(parts):
                    continue
                base = parts[: len(parts) - (node.level - 1)]
                module = base + (node.module.split(".") if node.module else [])
                targets = [".".join(module)] if module else [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("photogeom."):
                targets = [node.module.removeprefix("photogeom.")]
            elif isinstance(node, ast.Import):
                targets = [
                    a.name.removeprefix("photogeom.")
                    for a in node.names
                    if a.name.startswith("photogeom.")
                ]
            else:
                continue
            for target in targets:
                top = target.split(".")[0]
                if top in layer and layer[top] > layer[package]:
                    out.setdefault((package, target), []).append(str(rel))
    return out


def test_every_package_has_a_layer():
    found = {p.relative_to(SRC).parts[0].removesuffix(".py") for p in SRC.rglob("*.py")}
    missing = sorted(found - set(_layer()) - {"__init__", "__main__", "_lazy"})
    assert not missing, missing


def test_imports_into_a_lower_layer_are_the_shared_helpers():
    # the README said that each layer imports only those above it; camera, rpc, bundle and
    # calibration read through io, adjust and orientation format through report.format,
    # camera's COLMAP calibration files use bundle's COLMAP text
    found = downward_imports()
    unexpected = {
        k: v
        for k, v in found.items()
        if k not in SHARED and not (k[0] in READERS and k[1] in IO_HELPERS)
    }
    assert not unexpected, unexpected
    assert SHARED <= set(found), sorted(SHARED - set(found))  # the list stays the code's
