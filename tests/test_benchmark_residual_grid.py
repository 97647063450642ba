"""The folder part of ``benchmarks/residual_grid.py``: what it times, and what it leaves.

It generates a folder of JPEG images and writes the corrected folder with 1 and 2 workers:
about 100 MB per round for its default 8 images of 12 Mpx, which stayed in the temporary
folder after every run. It timed 1 worker, then 2, once: a change of the machine's load
between the two was reported as a speed-up or a slow-down.
"""

from __future__ import annotations

import argparse
import importlib.util
import tempfile
import types
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "residual_grid.py"


@pytest.fixture(scope="module")
def bench():
    pytest.importorskip("distributed")
    spec = importlib.util.spec_from_file_location("bench_residual_grid", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


class Cluster:
    """Stands for a ``LocalCluster`` (no worker processes started)."""

    def __init__(self, n_workers: int, **kwargs) -> None:
        self.scheduler_address = f"tcp://127.0.0.1:{8786 + n_workers}"

    def close(self) -> None:
        pass


def _folder_runs(bench, monkeypatch, failures: dict, cost=None) -> list:
    import distributed

    runs = []

    def correct_folder(src, dst, grids, **kwargs):
        if cost is not None:
            cost(Path(dst).name, kwargs["dask"])
        # what the real one does to the file system: one output file per image
        Path(dst).mkdir()
        for key in grids:
            (Path(dst) / f"{key}.jpg").write_bytes((Path(src) / f"{key}.jpg").read_bytes())
        runs.append((Path(src), len(grids), kwargs["dask"]))
        return types.SimpleNamespace(failures=failures)

    monkeypatch.setattr(distributed, "LocalCluster", Cluster)
    monkeypatch.setattr(bench, "correct_folder", correct_folder)
    return runs


@pytest.mark.parametrize("fails", [False, True])
def test_folder_benchmark_removes_its_images(bench, monkeypatch, tmp_path, capsys, fails):
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    runs = _folder_runs(bench, monkeypatch, {"IMG_001": "damaged"} if fails else {})
    args = argparse.Namespace(folder_images=3, folder_size=(160, 120), folder_rounds=1)
    if fails:
        with pytest.raises(AssertionError, match="damaged"):
            bench.bench_folder(args, np.random.default_rng(1))
    else:
        bench.bench_folder(args, np.random.default_rng(1))
        assert "3. folder of 3 JPEG images of 160 x 120 px" in capsys.readouterr().out
        # both clusters: a warm-up of one image per worker, then the whole folder
        assert [(n, address[-4:]) for _src, n, address in runs] == [
            (1, "8787"), (3, "8787"), (2, "8788"), (3, "8788")
        ]  # fmt: skip
    assert runs and all(src.parent.parent == temp for src, _n, _a in runs)
    assert list(temp.iterdir()) == []


def test_folder_rounds_alternate_and_the_median_ratio_is_reported(bench, monkeypatch, capsys):
    """Rounds of 1 and 2 workers in alternating order, one cluster at a time, the median of
    the per-round ratios: on a machine whose load grows during the run (each timed run
    20 % slower than the one before it), 1 worker then 2 workers once gave 1.67x for a true
    2x; the rounds give 1.67x, 2.29x and 1.80x, median 1.80x."""
    clock = {"now": 0.0, "timed": 0}
    order = []

    def cost(dst: str, address: str) -> None:
        n = int(address[-1]) - 6  # the fake clusters' ports: 8787, 8788
        if dst.startswith("out"):
            order.append(n)
            clock["now"] += (3.0 if n == 1 else 1.5) * (1 + 0.2 * clock["timed"])
            clock["timed"] += 1

    monkeypatch.setattr(bench, "time", types.SimpleNamespace(perf_counter=lambda: clock["now"]))
    runs = _folder_runs(bench, monkeypatch, {}, cost)
    args = argparse.Namespace(folder_images=2, folder_size=(160, 120), folder_rounds=3)
    bench.bench_folder(args, np.random.default_rng(1))
    out = capsys.readouterr().out
    assert order == [1, 2, 2, 1, 1, 2]
    # each timed run after the warm-up of its own cluster (one image per worker)
    assert [n for _s, n, _a in runs] == [1, 2, 2, 2, 2, 2, 1, 2, 1, 2, 2, 2]
    assert "3 round(s) of 1 and 2 workers" in out
    assert "3.00 / 1.80 s (1.67x), 4.80 / 2.10 s (2.29x), 5.40 / 3.00 s (1.80x)" in out
    assert "median speed-up 1.80x" in out
