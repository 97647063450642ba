"""``pip install ".[bench]"`` installs what the benchmark scripts import.

The README sends the reader to the ``bench`` extra for "the peers of the benchmarks". Every
third-party module that a script under ``benchmarks/`` imports is therefore a runtime
dependency or in that extra; the one exception is rpcm, whose own dependency (srtm4) does
not build everywhere and which is installed with ``--no-deps`` (the README and
``benchmarks/rpc.py`` say so).
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"
BENCHMARKS = ROOT / "benchmarks"

tomllib = pytest.importorskip("tomllib")  # Python 3.11+

pytestmark = pytest.mark.skipif(
    not (PYPROJECT.is_file() and BENCHMARKS.is_dir()),
    reason="pyproject.toml and benchmarks/ are not beside the tests",
)

#: Import names whose distribution is named otherwise.
DISTRIBUTION = {
    "PIL": "pillow",
    "cv2": "opencv-python-headless",
    "skimage": "scikit-image",
    "open3d": "open3d-cpu",
    "sksparse": "sksparse-minimal",
}

#: Installed by hand, without its dependencies (srtm4 is a stand-in module of rpc.py).
BY_HAND = {"rpcm", "srtm4"}


def _names(requirements: list[str]) -> set[str]:
    """Distribution names of PEP 508 requirement strings, lower case."""
    return {re.match(r"[A-Za-z0-9._-]+", r).group(0).lower() for r in requirements}


def _imported(path: Path) -> set[str]:
    """Top-level modules imported anywhere in ``path`` (absolute imports only)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


def test_bench_extra_installs_every_module_the_benchmarks_import():
    # bundle.py and bundle_io.py compare against pycolmap, scale.py needs laspy and dask,
    # residual_grid.py a Dask LocalCluster: none was in the extra, so after
    # pip install ".[bench]" the pycolmap rows of benchmarks/bundle.py read
    # "failed: ['ImportError: ...']" and benchmarks/scale.py stopped at its first import
    project = tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))["project"]
    installed = _names(project["dependencies"]) | _names(project["optional-dependencies"]["bench"])
    missing = []
    for script in sorted(BENCHMARKS.glob("*.py")):
        for module in sorted(_imported(script)):
            if module in sys.stdlib_module_names or module == "photogeom" or module in BY_HAND:
                continue
            dist = DISTRIBUTION.get(module, module).lower()
            if dist not in installed:
                missing.append(f"{script.name}: {module} ({dist})")
    assert not missing, missing
