"""The folder part of ``benchmarks/residual_grid.py`` leaves nothing behind.

It generates a folder of JPEG images and writes the corrected folder twice (1 and 2
workers): about 100 MB for its default 8 images of 12 Mpx, which stayed in the temporary
folder after every run.
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


def _folder_runs(bench, monkeypatch, failures: dict) -> list:
    import distributed

    runs = []

    def correct_folder(src, dst, grids, **kwargs):
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
    args = argparse.Namespace(folder_images=3, folder_size=(160, 120))
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
