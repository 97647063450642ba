"""Estimation time of photogeom's transformations against scikit-image, in one run.

For 10, 1e3 and 1e6 point pairs and the 2D affine, 2D projective and 3D similarity:

* photogeom ``estimate_transform(..., statistics=False)`` ("bare": the same least-squares
  estimate - the projective models with their nonlinear adjustment - without statistics;
  like for like with scikit-image, which returns a bare estimate);
* photogeom ``estimate_transform(...)`` with the full statistics (covariance, residuals,
  redundancy numbers, normalised residuals, textbook parameters);
* scikit-image's estimators (``AffineTransform``, ``ProjectiveTransform``,
  ``SimilarityTransform`` in 3D; ``from_estimate`` where available, else ``estimate``);

and the 3D similarity from 1e6 pairs against the time numpy needs to sum both input arrays
once. Targets: bare / scikit-image <= 1 everywhere; bare 1e6 similarity <= 3x the sum.

Times are medians of repeated calls (after warm-up calls; none for 1e6 points). For 10
points the contenders are timed in 150 interleaved rounds of 20 calls each and the ratio is
the median of the per-round ratios (a shared machine's speed drifts by tens of per cent
within seconds, which blocks timed one after the other would mistake for a difference);
for more points each contender is timed in its own block (a multithreaded peer leaves BLAS
threads spinning after a big call). Ratios < 1 mean photogeom is faster. Run::

    python benchmarks/transforms.py            # a few minutes
    python benchmarks/transforms.py --quick    # sizes 10 and 1e3 only
    python benchmarks/transforms.py --threads 1   # single-threaded BLAS
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable


def _parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description="photogeom vs scikit-image: estimation time")
    parser.add_argument("--quick", action="store_true", help="sizes 10 and 1e3 only")
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="BLAS threads (sets OPENBLAS/OMP/MKL_NUM_THREADS before numpy is imported)",
    )
    return parser.parse_args()


ARGS = _parse_args() if __name__ == "__main__" else None
if ARGS is not None and ARGS.threads:
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(ARGS.threads)

import numpy as np  # noqa: E402

try:
    import skimage
    import skimage.transform as sktf
except ImportError:  # pragma: no cover - optional peer
    sys.exit("scikit-image is needed: pip install '.[bench]'")

import photogeom  # noqa: E402
from photogeom.estimation import estimate_transform  # noqa: E402

SIZES = (10, 1_000, 1_000_000)
REPEATS = {10: 101, 1_000: 31, 1_000_000: 5}
#: Up to this many points the contenders are timed in interleaved rounds (see
#: :func:`interleaved_medians`): ratios are medians over rounds of the per-round ratio.
INTERLEAVED_MAX = 100
INTERLEAVED_ROUNDS = 150
INTERLEAVED_BLOCK = 20
#: skimage's 2D affine/projective estimators take a full SVD of the (2n, 9) design matrix,
#: which allocates a (2n, 2n) matrix; above this many bytes they are not run.
SKIMAGE_MEMORY_LIMIT = 4 * 2**30


def median_time(fn: Callable[[], object], repeats: int, warm_up: bool = True) -> float:
    """Median wall time of ``fn()`` in seconds (after one warm-up call if ``warm_up``)."""
    if warm_up:
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def blocked_medians(
    fns: list[Callable[[], object] | None], repeats: int, warm_up: bool = True
) -> list[float | None]:
    """:func:`median_time` of each function in turn (None entries give None). Blocks, not
    rounds: a multithreaded peer leaves BLAS threads spinning for a while after each call,
    which would slow down whatever runs right after it on a small machine."""
    return [None if f is None else median_time(f, repeats, warm_up) for f in fns]


def interleaved_medians(
    fns: list[Callable[[], object] | None], rounds: int, block: int
) -> tuple[list[float | None], list[float | None]]:
    """For small problems: ``rounds`` rounds, each timing a block of ``block`` calls of every
    function in turn (the order rotating from round to round), so that all contenders see
    the same machine state (a shared machine's speed drifts by tens of per cent within
    seconds). Returns the median time per call of each function and the median over rounds
    of each function's time divided by the last one's (None entries give None)."""
    live = [i for i, f in enumerate(fns) if f is not None]
    for i in live:  # warm-up
        for _ in range(block):
            fns[i]()
    times: dict[int, list[float]] = {i: [] for i in live}
    for r in range(rounds):
        k = r % len(live)
        for i in live[k:] + live[:k]:
            f = fns[i]
            t0 = time.perf_counter()
            for _ in range(block):
                f()
            times[i].append((time.perf_counter() - t0) / block)
    medians = [statistics.median(times[i]) if i in times else None for i in range(len(fns))]
    ref = times.get(len(fns) - 1)
    ratios = [
        None if ref is None or i not in times
        else statistics.median(a / b for a, b in zip(times[i], ref))
        for i in range(len(fns))
    ]
    return medians, ratios


def skimage_estimator(cls):
    """``f(src, dst)`` estimating ``cls`` with the API of the installed scikit-image."""
    if hasattr(cls, "from_estimate"):

        def f(src, dst):
            tf = cls.from_estimate(src, dst)
            if not tf:  # FailedEstimation is falsy
                raise RuntimeError(f"scikit-image {cls.__name__}: {tf}")
            return tf

        return f, "from_estimate"

    def g(src, dst):
        tf = cls(dimensionality=src.shape[1]) if cls is sktf.SimilarityTransform else cls()
        if not tf.estimate(src, dst):
            raise RuntimeError(f"scikit-image {cls.__name__}.estimate failed")
        return tf

    return g, "estimate"


def data(model: str, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Noisy point pairs of a realistic transformation of each kind."""
    if model == "affine2d":
        src = rng.uniform(0, 4000, (n, 2))
        A = np.array([[0.95, -0.07], [0.09, 1.03]])
        dst = src @ A.T + [125.0, 130.0]
    elif model == "projective2d":
        src = rng.uniform(0, 4000, (n, 2))
        H = np.array([[0.97, -0.03, 6.4], [-0.016, 0.97, 4.5], [-1e-5, -3e-5, 1.0]])
        h = np.column_stack([src, np.ones(n)]) @ H.T
        dst = h[:, :2] / h[:, 2:]
    else:  # similarity3d: model coordinates -> UTM-like coordinates
        src = rng.uniform(-1, 1, (n, 3))
        R = photogeom.opk_matrix(0.3, -0.2, 2.5).T
        dst = 250.0 * src @ R.T + [512_000.0, 4_215_000.0, 350.0]
    return src, dst + rng.normal(0, 0.01, dst.shape)


def main(args: argparse.Namespace) -> None:
    sizes = SIZES[:2] if args.quick else SIZES
    rng = np.random.default_rng(42)

    peers = {
        "affine2d": sktf.AffineTransform,
        "projective2d": sktf.ProjectiveTransform,
        "similarity3d": sktf.SimilarityTransform,
    }
    api = skimage_estimator(sktf.AffineTransform)[1]
    print(
        f"photogeom {photogeom.__version__} vs scikit-image {skimage.__version__} "
        f"({api}); numpy {np.__version__}; Python {platform.python_version()}; "
        f"{platform.machine()}; BLAS threads: "
        f"{os.environ.get('OPENBLAS_NUM_THREADS', 'default')}"
    )
    print(
        "median wall time per estimation; bare = statistics=False, full = with statistics;\n"
        "ratio = photogeom / scikit-image (< 1: photogeom faster; bare/sk is the target);\n"
        f"up to {INTERLEAVED_MAX} points: median of per-round ratios over "
        f"{INTERLEAVED_ROUNDS} interleaved rounds\n"
    )
    header = (
        f"{'model':<14}{'n':>10}{'bare':>12}{'full':>12}{'scikit-image':>16}"
        f"{'bare/sk':>9}{'full/sk':>9}"
    )
    print(header)
    print("-" * len(header))
    big_similarity = None
    for model, cls in peers.items():
        peer, _ = skimage_estimator(cls)
        for n in sizes:
            src, dst = data(model, n, rng)
            reps = REPEATS[n]
            big = n >= 100_000  # no warm-up for the big runs (seconds each)
            full_svd_bytes = (2 * n) ** 2 * 8
            skip_peer = model != "similarity3d" and full_svd_bytes > SKIMAGE_MEMORY_LIMIT
            contenders = [
                lambda s=src, d=dst, m=model: estimate_transform(m, s, d, statistics=False),
                lambda s=src, d=dst, m=model: estimate_transform(m, s, d),
                None if skip_peer else (lambda s=src, d=dst, f=peer: f(s, d)),
            ]
            if n <= INTERLEAVED_MAX:
                (bare, full, theirs), (q_bare, q_full, _) = interleaved_medians(
                    contenders, INTERLEAVED_ROUNDS, INTERLEAVED_BLOCK
                )
            else:
                bare, full, theirs = blocked_medians(contenders, reps, not big)
                q_bare = q_full = None
                if not skip_peer:
                    q_bare, q_full = bare / theirs, full / theirs
            if skip_peer:
                peer_text = f"n/a ({full_svd_bytes / 2**40:.0f} TiB)"
                r_bare = r_full = "-"
            else:
                peer_text = _ms(theirs)
                r_bare, r_full = f"{q_bare:.2f}", f"{q_full:.2f}"
            print(
                f"{model:<14}{n:>10,}{_ms(bare):>12}{_ms(full):>12}{peer_text:>16}"
                f"{r_bare:>9}{r_full:>9}",
                flush=True,
            )
            if model == "similarity3d" and n == 1_000_000:
                t_sum = median_time(lambda s=src, d=dst: (s.sum(), d.sum()), 11)
                big_similarity = (bare, full, t_sum)
    print()
    if any(n**2 * 32 > SKIMAGE_MEMORY_LIMIT for n in sizes):
        print(
            "n/a: scikit-image's AffineTransform/ProjectiveTransform take a full SVD of the "
            "(2n, 9) design matrix,\n     whose U factor alone needs (2n)^2 x 8 bytes; "
            "they were not run at that size."
        )
    if big_similarity is not None:
        bare, full, t_sum = big_similarity
        print(
            f"similarity3d from 1e6 pairs vs numpy sum of both input arrays once "
            f"({_ms(t_sum)}):\n"
            f"  bare {_ms(bare)}: ratio {bare / t_sum:.1f} (target <= 3)\n"
            f"  full {_ms(full)}: ratio {full / t_sum:.1f} (residuals, redundancy numbers and "
            "normalised residuals of 3e6 observations)"
        )


def _ms(t: float) -> str:
    return f"{t * 1e3:.3g} ms" if t < 1 else f"{t:.3g} s"


if __name__ == "__main__":
    main(ARGS)
