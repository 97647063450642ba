"""Benchmark: time and peak memory of grids inside the bundle adjustment.

Simulates a block (:func:`photogeom.simulate.uav_block`), adjusts it with a Brown
self-calibration, then estimates per-image grids inside the adjustment
(:func:`photogeom.calibration.adjust_with_grids`, ``sigma_constraint`` 1 px,
``sigma_temporal`` 0.3 px) and prints the time of that call and the peak resident memory of
the process (``ru_maxrss``; the simulation and the first adjustment included, far below the
grids' share on the sizes below).

Run, each in a fresh process (the peak is the process's):

``python benchmarks/residual_grid_in_adjustment_memory.py --preset FC300S --strips 2
--images 3 --spacing 100`` (6 images of 4000 x 3000 px, 1271 nodes per grid);
``--preset ILCE-7RM2 --strips 4 --images 10 --spacing 500`` (40 images of 42 Mpx);
``--preset ILCE-7RM2 --size study --spacing 500`` (the study's 250 images; minutes).
``--sigma-amplitude none``: grids without an amplitude, where the datum conditions are
dense blocks.
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import photogeom as pg


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="FC300S")
    ap.add_argument("--size", choices=("small", "study"), default="small")
    ap.add_argument("--strips", type=int, default=2)
    ap.add_argument("--images", type=int, default=3, help="images per strip (small size)")
    ap.add_argument("--spacing", type=float, default=100.0, help="grid spacing, px")
    ap.add_argument("--sigma-amplitude", default="residuals", help="px, 'residuals' or 'none'")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    sa = {"none": None, "residuals": "residuals"}.get(a.sigma_amplitude, a.sigma_amplitude)
    sa = float(sa) if isinstance(sa, str) and sa != "residuals" else sa
    kw = {} if a.size == "study" else {"strips": a.strips, "images_per_strip": a.images}
    sim = pg.simulate.uav_block(a.preset, seed=a.seed, size=a.size, **kw)
    first = pg.bundle_adjust(sim.block)
    t0 = time.perf_counter()
    ga = pg.calibration.adjust_with_grids(
        first.block, a.spacing, sigma_constraint=1.0, sigma_temporal=0.3, sigma_amplitude=sa
    )
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # kB on Linux
    layout = next(g for g in ga.grids.values()).layout
    print(
        f"load average {os.getloadavg()[0]:.1f}; {a.preset}, {sim.block.n_images} images, "
        f"{a.spacing:g} px ({layout.n_nodes} nodes per grid), sigma_amplitude {sa}: "
        f"{ga.n_unknowns} unknowns, {ga.iterations} iterations, sigma0 {ga.sigma0:.4f}, "
        f"{seconds:.1f} s, peak memory {peak / 1e9:.2f} GB"
    )


if __name__ == "__main__":
    main()
