"""Several threads at once: estimators and writers give the single-threaded results and leave
no process-wide setting (BLAS thread limits, umask) changed."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import photogeom as pg
from photogeom.io import read_point_pairs
from photogeom.orientation.absolute import LARGE_N
from photogeom.rpc import read_rpc

threadpoolctl = pytest.importorskip("threadpoolctl")


def _blas_limits() -> list[tuple[str, int]]:
    return [(i["filepath"], i["num_threads"]) for i in threadpoolctl.threadpool_info()
            if i["user_api"] == "blas"]  # fmt: skip


def _umask() -> int:
    """The umask read from /proc (never set: that is what is checked)."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    raise AssertionError("no Umask line")


def _scene(seed: int):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(LARGE_N + 1000, 3)) * 50
    R = pg.opk_matrix(0.1 * seed, -0.2, 0.3)
    X = 1.0001 * x @ R.T + [1000.0, 2000.0, 30.0] + rng.normal(0, 0.01, x.shape)
    return x, X


def _work(seed: int, directory) -> dict:
    """One large absolute orientation (the one-pass moments path), one 2D estimate, and two
    atomic writes (an RPC file and a pair of reports written as one)."""
    x, X = _scene(seed)
    fit = pg.absolute_orientation(x, X, method="svd")
    pairs = read_point_pairs(pg.datasets.path("lecture_fiducials"))
    f2 = pg.estimate_transform("similarity2d", pairs.source, pairs.target)
    rpc = read_rpc(pg.datasets.path("ikonos"))
    path = rpc.write(directory / f"rpc{seed}.txt")
    from photogeom.io.atomic import atomic_write_texts

    atomic_write_texts([(directory / f"a{seed}.txt", "a" * seed), (directory / f"b{seed}.txt", "")])
    return {
        "rotation": fit.rotation, "scale": fit.scale, "translation": fit.translation,
        "sigma0": fit.sigma0, "params2d": np.array(list(f2.params.values())),
        "rpc_text": path.read_text(), "mode": path.stat().st_mode & 0o777,
    }  # fmt: skip


def test_eight_threads_give_single_threaded_results(tmp_path):
    seeds = list(range(1, 9))
    serial_dir = tmp_path / "serial"
    serial_dir.mkdir()
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        limits = _blas_limits()
        umask = _umask()
        serial = {s: _work(s, serial_dir) for s in seeds}
        assert _blas_limits() == limits
        par_dir = tmp_path / "parallel"
        par_dir.mkdir()
        barrier = threading.Barrier(8)

        def run(s):
            barrier.wait()
            return _work(s, par_dir)

        for _ in range(2):
            with ThreadPoolExecutor(8) as ex:
                parallel = dict(zip(seeds, ex.map(run, seeds)))
            assert _blas_limits() == limits  # the BLAS limits restored, not left at 1
            assert _umask() == umask
        for s in seeds:
            for key, value in serial[s].items():
                if isinstance(value, np.ndarray):
                    np.testing.assert_array_equal(parallel[s][key], value)
                else:
                    assert parallel[s][key] == value, key
        assert serial[1]["mode"] == 0o666 & ~umask
        leftovers = [p.name for p in par_dir.iterdir() if p.name.startswith(".")]
        assert leftovers == []


def test_cholmod_factorisations_in_threads_give_the_single_threaded_results():
    """CHOLMOD (bound to an optimised BLAS, photogeom.adjust.sparse) factorising big
    supernodes in several threads at once."""
    import sys
    from pathlib import Path

    from photogeom.adjust.sparse import HAVE_CHOLMOD, factorize

    sys.path.insert(0, str(Path(__file__).parent))
    from sparse_systems import banded_dense_blocks

    if not HAVE_CHOLMOD:
        pytest.skip("CHOLMOD (sksparse-minimal) not installed")

    def solve(seed):
        N = banded_dense_blocks(nb=6, seed=seed)
        rhs = np.random.default_rng(100 + seed).standard_normal(N.shape[0])
        return factorize(N, backend="cholmod").solve(rhs)

    seeds = list(range(8))
    alone = [solve(s) for s in seeds]
    before = _blas_limits()
    with ThreadPoolExecutor(4) as ex:
        together = list(ex.map(solve, seeds))
    for a, t in zip(alone, together):
        np.testing.assert_allclose(t, a, rtol=1e-12, atol=1e-15)
    assert _blas_limits() == before
