"""A local Dask cluster started from a script without the main guard (docs run).

docs/crs-and-clouds.md ran ``map_items(..., scheduler="local")`` at the top level of the
snippet. In a script the local cluster's worker processes import the script again, and the
call ended in distributed's ``RuntimeError: Nanny failed to start.``, naming neither the
cause nor the fix. Now a :class:`PhotogeomError` names the main guard and
``scheduler="threads"``, and the snippet carries the guard.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytest.importorskip("distributed")

SRC = Path(__file__).resolve().parents[1] / "src"

SCRIPT = """
import photogeom as pg


def double(x):
    return 2 * x

{body}
"""

CALL = (
    "try:\n"
    "    pg.distributed.map_items(double, [1, 2], scheduler='local:1')\n"
    "except pg.PhotogeomError as exc:\n"
    "    print('PhotogeomError:', exc)\n"
    "else:\n"
    "    print('RESULT ok')\n"
)


def _run(tmp_path: Path, body: str) -> subprocess.CompletedProcess:
    script = tmp_path / "job.py"
    script.write_text(SCRIPT.format(body=body), encoding="utf-8")
    env = dict(os.environ, PYTHONPATH=str(SRC), OPENBLAS_NUM_THREADS="1")
    return subprocess.run(
        [sys.executable, str(script)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_local_cluster_without_main_guard_names_the_guard(tmp_path):
    out = _run(tmp_path, CALL)
    lines = [line for line in out.stdout.splitlines() if line.startswith("PhotogeomError:")]
    assert lines, (out.stdout[-2000:], out.stderr[-2000:])
    message = lines[-1]
    assert "did not start" in message
    assert 'if __name__ == "__main__":' in message
    assert "scheduler='threads'" in message and "--scheduler threads" in message


def test_local_cluster_with_main_guard_runs(tmp_path):
    out = _run(tmp_path, "if __name__ == '__main__':\n" + textwrap.indent(CALL, "    "))
    assert "RESULT ok" in out.stdout, (out.stdout[-2000:], out.stderr[-2000:])


def test_documented_map_items_snippet_has_the_guard():
    text = (Path(__file__).resolve().parents[1] / "docs" / "crs-and-clouds.md").read_text(
        encoding="utf-8"
    )
    start = text.index("res = pg.distributed.map_items(")
    guard = text.rfind('if __name__ == "__main__":', 0, start)
    assert guard != -1 and start - guard < 200
