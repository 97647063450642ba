"""Absolute orientation benchmark: every method, batched minimal solves, large n, and peers.

Run:  python benchmarks/absolute_orientation.py            (about two minutes)
      python benchmarks/absolute_orientation.py --quick    (smaller sizes, for a smoke run)

Prints, from one run on this machine:

1. single solves at n = 3, 18, 1000 of every method (parameters only, ``statistics=False``;
   also the SVD with statistics), and of the peers that are installed: scikit-image
   ``SimilarityTransform.from_estimate`` (3D), OpenCV ``estimateAffine3D(..., force_rotation)``
   (Umeyama with scale), Open3D ``TransformationEstimationPointToPoint(with_scaling=True)``;
   ratios peer / ours (SVD). All of them are timed in interleaved rounds (a block of calls
   of each in turn, the order rotating) and each reports its fastest block: on a shared
   machine the speed drifts by tens of per cent within seconds, which separate blocks per
   method would mistake for a difference between them (sections 2 and 3 report medians
   of repeated calls);
2. 1e5 three-point problems solved in one batched call vs a Python loop of single solves;
3. n = 1e6 and 1e7: time of every method (without and with statistics) against the time numpy
   needs to sum both input arrays once and against the SVD, peak memory (tracemalloc) against
   the size of the input, and the peers at 1e6 (``--large-only`` runs this section alone).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import tracemalloc

import numpy as np
import scipy.linalg.lapack
from scipy.spatial.transform import Rotation

import photogeom as pg
from photogeom.orientation import METHODS


def median_time(fn, min_time: float = 0.3, min_reps: int = 5, max_reps: int = 100000) -> float:
    """Median seconds per call over repeated calls (after one warm-up call)."""
    fn()
    times = []
    start = time.perf_counter()
    while len(times) < max_reps and (
        len(times) < min_reps or time.perf_counter() - start < min_time
    ):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def problem(n: int, seed: int = 0, noise: float = 0.01):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    x = rng.uniform(-50, 50, (n, 3))
    X = 1.7 * x @ R.T + np.array([100.0, -200.0, 30.0]) + rng.normal(scale=noise, size=(n, 3))
    return x, X, R


def peers():
    """name -> callable(x, X) returning something with the rotation (installed peers only)."""
    out = {}
    try:
        from skimage.transform import SimilarityTransform

        out["scikit-image SimilarityTransform"] = lambda x, X: SimilarityTransform.from_estimate(
            x, X
        )
    except ImportError:
        print("scikit-image: not installed (pip install scikit-image)")
    try:
        import cv2

        def opencv(x, X):
            return cv2.estimateAffine3D(x, X, force_rotation=True)

        out[f"OpenCV {cv2.__version__} estimateAffine3D"] = opencv
    except (ImportError, TypeError):
        print("OpenCV: not installed or no estimateAffine3D(src, dst, force_rotation)")
    try:
        import open3d as o3d

        est = o3d.pipelines.registration.TransformationEstimationPointToPoint(with_scaling=True)

        def open3d(x, X):
            ps = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(x))
            pt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(X))
            idx = np.arange(x.shape[0], dtype=np.int32)
            corr = o3d.utility.Vector2iVector(np.column_stack([idx, idx]))
            return est.compute_transformation(ps, pt, corr)

        out[f"Open3D {o3d.__version__} point-to-point (from numpy)"] = open3d
    except ImportError as exc:
        print(f"Open3D: not importable ({exc}); pip install open3d-cpu (needs libusb-1.0)")
    return out


FLOOR = "floor: bare SVD solution, 8 numpy/LAPACK calls"


def svd_floor(x, X):
    """The SVD solution (s, R, t) in the fewest numpy calls, with no input checks, no
    degeneracy or reflection test and no result object: what any numpy implementation
    must at least spend per call (the lower bound for the single-solve ratios)."""
    n = x.shape[0]
    Z = np.concatenate((x, X), axis=1)
    mu = Z.sum(axis=0) / n
    Zr = Z - mu
    C = Zr.T @ Zr
    u, S, vt, _ = scipy.linalg.lapack.dgesvd(C[:3, 3:])
    R = vt.T @ u.T
    c = C.diagonal()
    s = S.sum() / c[:3].sum()
    return s, R, mu[3:] - s * (R @ mu[:3])


def interleaved_fastest(fns: dict, rounds: int, block_time: float = 2e-3) -> dict:
    """Fastest seconds per call of each function, timed in interleaved rounds.

    Each round times a block of calls of every function in turn (the order rotating from
    round to round), so that all of them see the same machine state: on a shared machine the
    speed drifts by tens of per cent within seconds, which blocks of one function after the
    other would mistake for a difference between the functions. A block lasts about
    ``block_time`` seconds (its number of calls from a warm-up call); the result for each
    function is its fastest block over the rounds, per call.
    """
    names = list(fns)
    block = {}
    for name in names:  # warm-up, and the calls per block
        fns[name]()
        t0 = time.perf_counter()
        fns[name]()
        block[name] = max(1, round(block_time / max(time.perf_counter() - t0, 1e-7)))
    best = dict.fromkeys(names, float("inf"))
    for r in range(rounds):
        k = r % len(names)
        for name in names[k:] + names[:k]:
            f, m = fns[name], block[name]
            t0 = time.perf_counter()
            for _ in range(m):
                f()
            best[name] = min(best[name], (time.perf_counter() - t0) / m)
    return best


def single_contenders(x, X, peer_fns: dict) -> dict:
    """name -> call of every method, the SVD with statistics, the peers and the floor."""
    fns = {m: (lambda m=m: pg.absolute_orientation(x, X, m, statistics=False)) for m in METHODS}
    fns["svd with statistics"] = lambda: pg.absolute_orientation(x, X, "svd")
    for name, fn in peer_fns.items():
        fns[name] = lambda fn=fn: fn(x, X)
    fns[FLOOR] = lambda: svd_floor(x, X)
    return fns


def section_single(sizes, rounds):
    print(f"\n1. single solves: microseconds per call (fastest of {rounds} interleaved rounds)")
    peer_fns = peers()
    head = f"{'method':<48}" + "".join(f"{f'n={n}':>12}" for n in sizes)
    print(head)
    rows = {}
    for n in sizes:
        x, X, _ = problem(n, seed=n)
        for name, t in interleaved_fastest(single_contenders(x, X, peer_fns), rounds).items():
            rows.setdefault(name, []).append(t)
    for name, ts in rows.items():
        print(f"{name:<48}" + "".join(f"{t * 1e6:>12.1f}" for t in ts))
    print("ratios (fastest time of the other / fastest time of our SVD, parameters only; "
          "> 1: ours faster)")
    ours = rows["svd"]
    for name, ts in rows.items():
        if name == "svd":
            continue
        print(f"  {name:<46}" + "".join(f"{t / o:>12.2f}" for t, o in zip(ts, ours)))
    for name, ts in rows.items():
        if name.startswith("scikit-image"):
            print("ratio scikit-image / floor (what a check-free numpy implementation "
                  "would show)")
            print(f"  {'':<46}" + "".join(f"{t / f:>12.2f}" for t, f in zip(ts, rows[FLOOR])))
    return rows


def section_batch(B, loop_n, min_time):
    print(f"\n2. {B:.0e} three-point problems: one batched call vs a Python loop of single solves")
    rng = np.random.default_rng(1)
    R = Rotation.random(B, random_state=1).as_matrix()
    x = rng.uniform(-10, 10, (B, 3, 3))
    X = 2.0 * np.matmul(x, np.swapaxes(R, 1, 2)) + 5 + rng.normal(scale=0.01, size=(B, 3, 3))
    print(f"{'method':<18}{'batch [s]':>12}{'loop [s]':>12}{'ratio':>10}   (loop over all {B} "
          f"problems for svd, else {loop_n} extrapolated)")
    for m in ("svd", "gauss-helmert", "quaternion", "dual-quaternion", "closed-form"):
        tb = median_time(lambda m=m: pg.absolute_orientation_batch(x, X, m), min_time, min_reps=3)
        count = B if m == "svd" else loop_n
        t0 = time.perf_counter()
        for i in range(count):
            pg.absolute_orientation(x[i], X[i], m, statistics=False)
        tl = (time.perf_counter() - t0) / count * B
        print(f"{m:<18}{tb:>12.3f}{tl:>12.3f}{tl / tb:>10.1f}")
    res = pg.absolute_orientation_batch(x, X, "svd")
    print(f"   batched svd: max |R - R_true| = {np.nanmax(np.abs(res.rotation - R)):.1e} "
          f"(noise 0.01 on 3 points), {int(res.valid.sum())} of {B} valid")


def peak_memory(fn) -> float:
    """Peak bytes allocated (tracemalloc: numpy reports its buffers) during one call."""
    tracemalloc.start()
    try:
        fn()
        return float(tracemalloc.get_traced_memory()[1])
    finally:
        tracemalloc.stop()


def section_large(sizes):
    print("\n3. large n: time against summing both arrays once; peak memory against the input")
    peer_fns = peers()
    for n in sizes:
        rng = np.random.default_rng(n)
        R = Rotation.random(random_state=3).as_matrix()
        x = rng.normal(scale=50.0, size=(n, 3))
        X = 1.3 * x @ R.T + np.array([10.0, 20.0, 30.0]) + rng.normal(scale=0.01, size=(n, 3))
        reps = 7 if n <= 1_000_000 else 3
        ref = median_time(lambda x=x, X=X: (x.sum(), X.sum()), 0.0, min_reps=reps)
        size = x.nbytes + X.nbytes
        print(f"n = {n:.0e}: numpy x.sum() + X.sum(): {ref * 1e3:.1f} ms; "
              f"input {size / 1e6:.0f} MB")
        methods = ["svd", "quaternion", "dual-quaternion", "gauss-helmert", "closed-form",
                   "gauss-markov"]
        t_svd = None
        for stats in (False, True):
            for m in methods:
                if stats and n > 1_000_000 and m not in ("svd", "gauss-markov", "gauss-helmert"):
                    continue
                def call(m=m, x=x, X=X, stats=stats):
                    return pg.absolute_orientation(x, X, m, statistics=stats)

                t = median_time(call, 0.0, min_reps=reps if not stats else 3)
                mem = peak_memory(call) / size
                if m == "svd" and not stats:
                    t_svd = t
                label = m + (" with statistics" if stats else "")
                print(f"   {label:<34}{t * 1e3:>10.1f} ms {t / ref:>7.2f} x the sum "
                      f"{t / t_svd:>7.2f} x svd   peak memory {mem:5.2f} x the input")
        if n <= 1_000_000:
            Xu = X + np.array([5.0e5, 4.0e6, 0.0])  # UTM-sized target: exact centring first
            t = median_time(
                lambda x=x, Xu=Xu: pg.absolute_orientation(x, Xu, "svd", statistics=False),
                0.0, min_reps=reps,
            )
            label = "svd, UTM-sized target"
            print(f"   {label:<34}{t * 1e3:>10.1f} ms {t / ref:>7.2f} x the sum")
            for name, fn in peer_fns.items():
                t = median_time(lambda fn=fn, x=x, X=X: fn(x, X), 0.0, min_reps=3)
                print(f"   {name:<46}{t * 1e3:>10.1f} ms   {t / ref:>6.2f} x the sum")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (smoke run)")
    ap.add_argument("--large-only", action="store_true", help="only section 3 (large n)")
    args = ap.parse_args(argv)
    import numpy

    print(f"photogeom {pg.__version__}, numpy {numpy.__version__}, python {sys.version.split()[0]}")
    if args.large_only:
        section_large((1_000_000, 10_000_000))
    elif args.quick:
        section_single((3, 18), 10)
        section_batch(2000, 500, 0.05)
        section_large((100_000,))
    else:
        section_single((3, 18, 1000), 60)
        section_batch(100_000, 10_000, 0.5)
        section_large((1_000_000, 10_000_000))


if __name__ == "__main__":
    main()
