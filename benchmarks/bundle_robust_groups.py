"""Variance factors of the control points' and GNSS groups with a robust loss against least
squares, paired on the same Monte-Carlo redraws.

Simulated FC6310 block (2 strips of 3 images, 50 tie points per image, no local field);
each trial draws image noise of twice its a-priori sigma and adjusts the block with the
squared, Huber's and Cauchy's loss, variance components iterated. With ``--redraw images``
the control points' survey, the GNSS and the IMU observations keep the one realisation of
their errors that the simulation drew; with ``--redraw all`` they are redrawn in each trial
too. Printed per group and robust loss: the mean iterated factor, that of least squares
on the same trials (those in which all three converge and estimate the group) and their
paired difference with its sampling error.

    python benchmarks/bundle_robust_groups.py --trials 50 --redraw images
    python benchmarks/bundle_robust_groups.py --trials 60 --redraw all
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import photogeom as pg

LOSSES = ("squared", "huber", "cauchy")


def _trial(sim, rng: np.random.Generator, redraw: str):
    """The block of one trial (image noise twice its sigma; with ``redraw="all"`` the
    survey, GNSS and IMU redrawn from the truth with their sigmas)."""
    b, t = sim.block, sim.truth
    uv = sim.ideal + rng.normal(0, 1, sim.ideal.shape) * b.observations.sigma[:, None] * 2.0
    if redraw == "all":
        known = b.role != "tie"
        xyz = b.xyz.copy()
        xyz[known] = t.xyz[known] + rng.normal(0, 1, (int(known.sum()), 3)) * b.point_sigma[known]
        b = b.replace(
            xyz=xyz,
            gnss=t.gnss + rng.normal(0, 1, t.gnss.shape) * b.gnss_sigma,
            imu=t.imu + rng.normal(0, 1, t.imu.shape) * b.imu_sigma,
        )
    return b.with_observations(uv=uv)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--redraw", choices=("images", "all"), default="images")
    a = ap.parse_args()
    sim = pg.simulate.uav_block(
        "FC6310", seed=1, strips=2, images_per_strip=3, tie_points_per_image=50, local_field=0.0
    )
    rng = np.random.default_rng(11)
    runs = []
    t0 = time.perf_counter()
    for _ in range(a.trials):
        block = _trial(sim, rng, a.redraw)
        row = {}
        for loss in LOSSES:
            fit = pg.bundle_adjust(block, loss=loss, variance_components=True, snooping=False)
            vc = fit.variance_components
            row[loss] = (vc["factors"], bool(vc["converged"]), set(vc["not_estimated"] or ()))
        runs.append(row)
    print(f"{a.trials} trials, --redraw {a.redraw}, {time.perf_counter() - t0:.0f} s")
    for group in ("control", "gnss"):
        ok = [
            r
            for r in runs
            if all(r[m][1] and group in r[m][0] and group not in r[m][2] for m in LOSSES)
        ]
        ls = np.array([r["squared"][0][group] for r in ok])
        for loss in ("huber", "cauchy"):
            rob = np.array([r[loss][0][group] for r in ok])
            d = rob - ls
            se = d.std(ddof=1) / np.sqrt(d.size) if d.size > 1 else float("nan")
            print(
                f"{group:8s} {loss:7s} {d.size:3d} trials: {rob.mean():.3f} against least "
                f"squares {ls.mean():.3f}, paired difference {d.mean():+.4f} +- {se:.4f}"
            )


if __name__ == "__main__":
    main()
