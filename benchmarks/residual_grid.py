"""Benchmark: finite-element residual grids (fit, image correction, folders on Dask).

Measured in one run on the same machine:

1. grid fit of a block of ``--images`` images (default 250) of 7952 x 5304 px (42 Mpx, the
   ILCE-7RM2 of the UAV study) with a 100 px grid (55 x 81 = 4455 nodes) and
   ``--points`` simulated residuals per image (a smooth image-variant field plus noise):
   ``photogeom.calibration.fit_grids`` without cross-validation, and per image with 5-fold
   cross-validation and with the node standard deviations (selected inversion); the
   ratio against ``scipy.sparse.linalg.spsolve`` solving the same normal equations (the
   equations built by photogeom, so only the solve is compared);
2. correcting one 42 Mpx RGB image (uint8, bilinear): ``correct_image`` (field evaluated at
   every pixel + remap, in bands of rows) vs a bare ``cv2.remap`` with the maps precomputed;
   interleaved rounds, median of the per-round ratios. Target: within 1.5x;
3. a folder of ``--folder-images`` JPEG images (default 8 of 4000 x 3000 px) corrected on a
   Dask local cluster with 2 workers vs 1 worker (the clusters are started, and each of
   their workers has corrected one image, before the clock runs; reading, resampling,
   encoding and the atomic writes are timed, with the client's connection); in
   ``--folder-rounds`` rounds (default 3) of both, the order alternating (1 then 2
   workers, then 2 then 1, ...), one cluster at a time; the median of the per-round
   ratios. Target: at least 1.6x.

Run: ``python benchmarks/residual_grid.py`` (a few minutes). On a shared machine, the
parallel speed-up is bounded by the share of the cores this session gets: with Linux's
autogroup the cores are shared between sessions, so while another session is busy the
two workers (processes of this session) get no more CPU than one. The script prints the
load average next to the ratios.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from photogeom.calibration import correct_folder, correct_image, fit_grid, fit_grids
from photogeom.calibration.correction import remap_maps
from photogeom.calibration.grid import FiniteElementSystem

W, H = 7952, 5304


def simulated_block(n_images: int, n_points: int, rng) -> dict:
    """Residuals (computed - observed, px) of images with image-variant local fields."""
    out = {}
    for k in range(n_images):
        uv = np.column_stack([rng.uniform(0, W - 1, n_points), rng.uniform(0, H - 1, n_points)])
        x, y = uv[:, 0] / W, uv[:, 1] / H
        ph = rng.uniform(0, 2 * np.pi, 2)
        field = np.column_stack(
            [0.8 * np.sin(3 * x + ph[0]) * np.cos(2 * y), 0.6 * np.cos(2.5 * x * y + ph[1])]
        )
        out[f"IMG_{k:04d}"] = (uv, -field + rng.normal(0, 0.3, field.shape))
    return out


def bench_fit(args, rng) -> None:
    block = simulated_block(args.images, args.points, rng)
    t0 = time.perf_counter()
    grids = fit_grids(block, (W, H), 100.0, folds=0)
    t_fit = time.perf_counter() - t0
    g0 = next(iter(grids.values()))
    print(
        f"1. grid fit: {args.images} images of {W} x {H} px, {args.points} residuals each, "
        f"100 px grid ({g0.layout.ny} x {g0.layout.nx} nodes)"
    )
    print(
        f"   fit_grids (no cross-validation): {t_fit:.2f} s, "
        f"{1e3 * t_fit / args.images:.1f} ms/image"
    )
    sub = list(block.items())[: args.cv_images]
    t0 = time.perf_counter()
    for _k, (uv, r) in sub:
        fit_grid(uv, r, (W, H), 100.0, folds=5)
    t_cv = (time.perf_counter() - t0) / len(sub)
    print(
        f"   with 5-fold cross-validation: {1e3 * t_cv:.1f} ms/image ({len(sub)} images timed; "
        f"{t_cv * args.images:.1f} s for {args.images})"
    )
    t0 = time.perf_counter()
    for g in list(grids.values())[: args.cv_images]:
        g.node_std  # noqa: B018 - computed on first use
    t_std = (time.perf_counter() - t0) / len(sub)
    print(f"   node standard deviations (selected inversion): {1e3 * t_std:.1f} ms/image")
    from scipy.sparse.linalg import spsolve

    uv, r = sub[0][1]
    system = FiniteElementSystem(g0.layout, uv, np.ones(len(uv)), 1.0)
    rhs = np.asarray(system._AtP @ r)
    ours, peer = [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        FiniteElementSystem(g0.layout, uv, np.ones(len(uv)), 1.0).solve(r)
        ours.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        spsolve(system.N.tocsc(), rhs)
        peer.append(time.perf_counter() - t0)
    print(
        f"   one image, equations + factorisation + solve: {1e3 * min(ours):.1f} ms; "
        f"scipy spsolve of the built equations alone: {1e3 * min(peer):.1f} ms "
        f"(ratio {min(ours) / min(peer):.2f})"
    )


def bench_image(args, rng) -> None:
    uv = np.column_stack([rng.uniform(0, W - 1, 4000), rng.uniform(0, H - 1, 4000)])
    grid = fit_grid(uv, rng.normal(0, 0.5, (4000, 2)), (W, H), 100.0, folds=0)
    img = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    mx, my = remap_maps(grid)
    ratios, t_ours, t_cv = [], [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        a = correct_image(img, grid)
        t1 = time.perf_counter()
        b = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        t2 = time.perf_counter()
        t_ours.append(t1 - t0)
        t_cv.append(t2 - t1)
        ratios.append((t1 - t0) / (t2 - t1))
    diff = int(np.abs(a.astype(int) - b).max())
    print(f"2. correcting one {W} x {H} RGB image (bilinear), {args.repeat} interleaved rounds")
    print(
        f"   correct_image {statistics.median(t_ours):.3f} s, bare cv2.remap with precomputed "
        f"maps {statistics.median(t_cv):.3f} s: median ratio {statistics.median(ratios):.2f} "
        f"(target <= 1.5); max difference {diff} grey level(s)"
    )


def bench_folder(args, rng) -> None:
    # the inputs and the outputs of all runs (about 100 MB per round for 8 images of 12 Mpx)
    # are removed when the benchmark ends, also when it fails
    with tempfile.TemporaryDirectory(prefix="pg-grid-bench-") as tmp:
        rounds = _time_folder(args, rng, Path(tmp))
    fw, fh = args.folder_size
    ratios = [r[1] / r[2] for r in rounds]
    print(
        f"3. folder of {args.folder_images} JPEG images of {fw} x {fh} px on a Dask local cluster, "
        f"{len(rounds)} round(s) of 1 and 2 workers (order alternating)"
    )
    print(
        "   per round (1 worker / 2 workers): "
        + ", ".join(f"{r[1]:.2f} / {r[2]:.2f} s ({r[1] / r[2]:.2f}x)" for r in rounds)
    )
    print(
        f"   1 worker {statistics.median(r[1] for r in rounds):.2f} s, 2 workers "
        f"{statistics.median(r[2] for r in rounds):.2f} s: median speed-up "
        f"{statistics.median(ratios):.2f}x (target >= 1.6); load average "
        f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    )


def _time_folder(args, rng, tmp: Path) -> list[dict]:
    """Seconds to correct the folder of generated images in ``tmp`` on 1 and on 2 workers,
    per round (``{1: s, 2: s}``); the order of the two alternates between rounds so that a
    change of the machine's load in the course of the run falls on both alike."""
    from distributed import LocalCluster
    from PIL import Image

    fw, fh = args.folder_size
    src = tmp / "in"
    src.mkdir()
    grids = {}
    uv = np.column_stack([rng.uniform(0, fw - 1, 3000), rng.uniform(0, fh - 1, 3000)])
    for k in range(args.folder_images):
        base = cv2.resize(rng.integers(0, 256, (fh // 8, fw // 8, 3), dtype=np.uint8), (fw, fh))
        Image.fromarray(base).save(src / f"IMG_{k:03d}.jpg", quality=92)
        grids[f"IMG_{k:03d}"] = fit_grid(
            uv, rng.normal(0, 0.5, (3000, 2)), (fw, fh), 100.0, folds=0
        )
    rounds = []
    for r in range(args.folder_rounds):
        times = {}
        for n in (1, 2) if r % 2 == 0 else (2, 1):
            cluster = LocalCluster(
                n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0"
            )
            try:
                # warm-up: each worker imports photogeom and OpenCV once
                correct_folder(src, tmp / f"warm{n}-{r}", dict(list(grids.items())[:n]),
                               dask=cluster.scheduler_address, progress=False)  # fmt: skip
                t0 = time.perf_counter()
                res = correct_folder(src, tmp / f"out{n}-{r}", grids,
                                     dask=cluster.scheduler_address, progress=False)  # fmt: skip
                times[n] = time.perf_counter() - t0
                assert not res.failures, res.failures
            finally:
                cluster.close()
        rounds.append(times)
    return rounds


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--images", type=int, default=250)
    p.add_argument("--points", type=int, default=4000)
    p.add_argument("--cv-images", type=int, default=10)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--folder-images", type=int, default=8)
    p.add_argument("--folder-size", type=int, nargs=2, default=(4000, 3000))
    p.add_argument("--folder-rounds", type=int, default=3)
    p.add_argument("--only", choices=("fit", "image", "folder"))
    args = p.parse_args()
    rng = np.random.default_rng(1)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    if args.only in (None, "fit"):
        bench_fit(args, rng)
    if args.only in (None, "image"):
        bench_image(args, rng)
    if args.only in (None, "folder"):
        bench_folder(args, rng)


if __name__ == "__main__":
    main()
