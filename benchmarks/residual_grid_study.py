"""Benchmark: the UAV residual-grid study re-created on the simulator's three presets.

For ILCE-7RM2 (unstable camera, strong image-variant local fields), FC6310 and FC300S
(stable cameras, weak fields): simulate, adjust with Brown self-calibration, fit 100 px
grids per image, correct the observations, re-adjust with the exterior orientation and
calibration fixed, and measure: the mean height step between consecutive stereo models
(GSD) before and after, the reduction of the tie-point residual RMS, the share of the
100 px grid's step gain that a 2000 px grid gives, the closest-to-origin spacing of the
sweep (most frequent over the models; its cost is the least CPU time of up to three
timings of the grid fit and the correction, ``sweep_spacings``), the fitted field against
the true local field, and the check-point RMSE against the truth. The step, the 2000 px
share and the spacing are measured twice: on the corrected first observations, and on the
observations measured again (``sim.rematch``: fresh noise, as the study's re-matching of the
corrected images), where the grids cannot be credited with the noise they fitted. The
study's published numbers are printed beside ours: they are trends measured on real
blocks, ours on simulated re-creations.

Run: ``python benchmarks/residual_grid_study.py`` (small blocks, 2 strips of 8 images,
about a minute per preset on a loaded 2-core machine) or ``--size study`` for the study's
block sizes (250 / 195 / 82 images; long).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import photogeom as pg

PUBLISHED = {
    "ILCE-7RM2": {"step": "25 -> 10 (one model)", "grid": 100, "optimal": "200 (7 of 11)"},
    "FC6310": {"step": "3.2 -> 2.7 (mean)", "grid": 70, "optimal": "150 (7 of 10)"},
    "FC300S": {"step": "1.4 -> 1.2 (mean)", "grid": 70, "optimal": "150 (2 of 5)"},
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", choices=("small", "study"), default="small")
    ap.add_argument("--strips", type=int, default=2)
    ap.add_argument("--images", type=int, default=8, help="images per strip (small size)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--sweep", default="100,150,200,300,500,1000,2000")
    ap.add_argument("--presets", default="ILCE-7RM2,FC6310,FC300S")
    ap.add_argument(
        "--ties", type=float, default=None, help="tie points per image (default: the preset's)"
    )
    a = ap.parse_args()
    sweep = [float(x) for x in a.sweep.split(",")] if a.sweep else None
    print(f"load average {os.getloadavg()[0]:.1f}; size {a.size}")
    rows = []
    for name in a.presets.split(","):
        t0 = time.perf_counter()
        kw = {} if a.size == "study" else {"strips": a.strips, "images_per_strip": a.images}
        if a.ties is not None:
            kw["tie_points_per_image"] = a.ties
        r = pg.calibration.run_study(name, seed=a.seed, size=a.size, sweep=sweep, **kw)
        ev = r["evaluation"]
        sw = r["sweep"]
        chosen = ""
        if sw is not None:
            c = np.asarray(sw["choice"]["spacing"])
            chosen = f"{sw['spacing']:g} ({int(np.sum(c == sw['spacing']))} of {c.size})"
        cb, ca = ev["check_before"], ev["check_after"]
        rm = r["rematched"]
        chosen_r = ""
        if sw is not None:
            c = np.asarray(sw["choice_rematched"]["spacing"])
            best = sw["spacing_rematched"]
            chosen_r = f"{best:g} ({int(np.sum(c == best))} of {c.size})"
        rows.append(
            (
                name,
                r["images"],
                f"{ev['mean_step_before']:.2f} -> {ev['mean_step_after']:.2f} "
                f"({100 * ev['step_reduction']:.0f} %)",
                f"{100 * r['residual_reduction']:.0f} %",
                f"{r['coarse_share']:.2f} (step {r['coarse']['mean_step_after']:.2f})",
                chosen,
                f"{r['field']['block']['ratio']:.2f}",
                f"{np.linalg.norm(cb['rmse_gsd']):.2f} -> {np.linalg.norm(ca['rmse_gsd']):.2f}",
                f"{rm['mean_step_before']:.2f} -> {rm['mean_step_after']:.2f} "
                f"({100 * rm['step_reduction']:.0f} %)",
                f"{r['coarse_share_rematched']:.2f} "
                f"(step {r['coarse_rematched']['mean_step_after']:.2f})",
                chosen_r,
                f"{time.perf_counter() - t0:.0f} s",
            )
        )
        print(" | ".join(map(str, rows[-1])), flush=True)
        print("   published:", PUBLISHED[name])
        if sw is not None:
            cost = " ".join(f"{x:.2f}" for x in sw["time"])
            print(
                f"   sweep: {r['times']['sweep']:.0f} s wall; CPU s per spacing, the least of "
                f"{sw['timings']} timings: {cost}; re-adjustments "
                f"{float(np.sum(sw['time_readjust'])):.1f} s"
            )
    print()
    print(
        "| camera | images | step before -> after, GSD (ours) | residual RMS reduction | "
        "2000 px share of the 100 px step gain | optimal spacing (models) | "
        "field difference / field RMS | check RMSE, GSD | re-matched: step | re-matched: "
        "2000 px share | re-matched: optimal spacing | time |"
    )
    print("|---" * 12 + "|")
    for row in rows:
        print("| " + " | ".join(map(str, row)) + " |")


if __name__ == "__main__":
    main()
