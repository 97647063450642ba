"""Benchmark: which simulated local fields the study's published trends imply.

The study gives no residual values, so the simulator's presets choose the local fields
(docs/simulation.md). This script varies the two choices the trends depend on and measures
them on re-matched observations (``sim.rematch``: the grids meet fresh noise, as the study's
re-matching of its corrected images did):

* **Unstable camera** (ILCE-7RM2, 1.0 px fields): the spectrum of the fields, the slope of
  the coefficients' fall with the wave number (``local_field_slope``) and the highest wave
  number (``local_field_modes``). Printed: the step before and after 100 px grids, its
  reduction, the share of that gain a 2000 px grid gives, the residual reduction and the
  closest-to-origin spacing (most frequent over the models, then over the seeds).
* **Two components** (ILCE-7RM2): a smooth image-variant field (``local_field_smooth``: the
  four waves one cycle long across the image) beside a fine one (``local_field``, the
  preset's ``1 / |k|`` spectrum up to the wave number 6): splits of 1.0 px
  (``sqrt(smooth**2 + fine**2)``), then larger smooth components. Printed as for the
  unstable camera.
* **Stable cameras** (FC6310, FC300S): the fields' RMS (``local_field``). Printed: the step
  reduction of 100 px grids and the step after a 2000 px grid (the study: coarse grids make
  a stable block worse).

Every row is the mean over ``--seeds`` blocks of ``--strips`` x ``--images`` images with
``--ties`` tie points per image (:func:`photogeom.calibration.run_study`).

Run: ``python benchmarks/residual_grid_sensitivity.py [--part
unstable|twofield|stable|both|all] [--splits 0.6:0.8,0.8:0.6] [--seeds 1,2,3] [--ties 1000]``
(``both``: unstable and stable; ``all`` adds the two components; about 20 s per block on a
loaded 2-core machine).
"""

from __future__ import annotations

import argparse
import os
import time
from collections import Counter

import numpy as np

import photogeom as pg

SWEEP = (100, 150, 200, 300, 500, 1000, 2000)
SPECTRA = (  # (label, slope, modes)
    ("1/|k|, modes <= 6 (preset)", 1.0, 6),
    ("1/|k|^2, modes <= 6", 2.0, 6),
    ("1/|k|^3, modes <= 6", 3.0, 6),
    ("one wave per image (modes 1)", 1.0, 1),
)
AMPLITUDES = (0.15, 0.3, 0.5)
#: (smooth, fine) RMS, px: splits of about 1.0 px (sqrt(smooth**2 + fine**2)), then larger
#: smooth components (docs/residual-grid.md, "What the published trends imply")
SPLITS = (
    (0.6, 0.8),
    (0.8, 0.6),
    (0.9, 0.44),
    (0.95, 0.31),
    (1.2, 0.36),
    (1.5, 0.3),
    (1.5, 0.45),
    (2.0, 0.2),
    (2.0, 0.4),
    (2.0, 0.6),
    (2.0, 0.8),
)


def _run(preset: str, seeds, common: dict, **field) -> dict:
    """Means over seeds of the re-matched study numbers."""
    rows = []
    for s in seeds:
        r = pg.calibration.run_study(preset, seed=s, sweep=SWEEP, **common, **field)
        ev, rm, co = r["evaluation"], r["rematched"], r["coarse_rematched"]
        b = ev["mean_step_before"]
        rows.append(
            {
                "before": b,
                "after": rm["mean_step_after"],
                "reduction": 1.0 - rm["mean_step_after"] / b,
                "share": r["coarse_share_rematched"],
                "coarse_change": co["mean_step_after"] / b - 1.0,
                "residuals": r["residual_reduction"],
                "spacing": r["sweep"]["spacing_rematched"],
            }
        )
    out = {k: float(np.mean([x[k] for x in rows])) for k in rows[0] if k != "spacing"}
    out["spacing"] = Counter(x["spacing"] for x in rows).most_common(1)[0][0]
    out["spacings"] = [x["spacing"] for x in rows]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--part", choices=("unstable", "twofield", "stable", "both", "all"), default="both"
    )
    ap.add_argument(
        "--splits",
        default=",".join(f"{a:g}:{b:g}" for a, b in SPLITS),
        help="smooth:fine RMS pairs (px) of the two-component rows, comma-separated",
    )
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--ties", type=float, default=1000.0, help="tie points per image")
    ap.add_argument("--strips", type=int, default=2)
    ap.add_argument("--images", type=int, default=8, help="images per strip")
    a = ap.parse_args()
    seeds = [int(x) for x in a.seeds.split(",")]
    splits = [tuple(float(v) for v in x.split(":")) for x in a.splits.split(",")]
    common = {
        "strips": a.strips,
        "images_per_strip": a.images,
        "tie_points_per_image": a.ties,
    }
    print(
        f"load average {os.getloadavg()[0]:.1f}; {a.strips} x {a.images} images, "
        f"{a.ties:g} tie points per image, seeds {seeds}; re-matched observations"
    )
    head = (
        f"{'step before':>11s} {'after':>6s} {'reduction':>9s} {'2000 px share':>13s} "
        f"{'residuals':>9s} {'spacing (seeds)':>22s} {'s':>4s}"
    )

    def line(label: str, r: dict, t0: float) -> str:
        return (
            f"{label:30s} {r['before']:11.2f} {r['after']:6.2f} {-r['reduction']:+9.0%} "
            f"{r['share']:13.0%} {-r['residuals']:+9.0%} "
            f"{'/'.join(f'{x:g}' for x in r['spacings']):>22s} "
            f"{time.perf_counter() - t0:4.0f}"
        )

    if a.part in ("unstable", "both", "all"):
        print(
            "\nILCE-7RM2, 1.0 px fields (study: 25 -> 10 GSD, -60 %; 2000 px about 80 % of "
            "the gain; residuals up to -70 %; optimal 200 px)"
        )
        print(f"{'spectrum':30s} {head}")
        for label, slope, modes in SPECTRA:
            t0 = time.perf_counter()
            r = _run("ILCE-7RM2", seeds, common, local_field_slope=slope, local_field_modes=modes)
            print(line(label, r, t0), flush=True)
    if a.part in ("twofield", "all"):
        print(
            "\nILCE-7RM2, smooth + fine fields (local_field_smooth, local_field; the fine one "
            "1/|k|, modes <= 6)"
        )
        print(f"{'smooth / fine px (total)':30s} {head}")
        for smooth, fine in splits:
            t0 = time.perf_counter()
            r = _run("ILCE-7RM2", seeds, common, local_field=fine, local_field_smooth=smooth)
            label = f"{smooth:g} / {fine:g} ({np.hypot(smooth, fine):.2f})"
            print(line(label, r, t0), flush=True)
    if a.part in ("stable", "both", "all"):
        print(
            "\nStable cameras (study: FC6310 3.2 -> 2.7, -16 %, 2000 px up to 3.4, worse; "
            "FC300S 1.4 -> 1.2, -14 %)"
        )
        print(
            f"{'camera':8s} {'field px':>8s} {'step before':>11s} {'after':>6s} "
            f"{'reduction':>9s} {'2000 px':>8s} {'spacing (seeds)':>22s} {'s':>4s}"
        )
        for name in ("FC6310", "FC300S"):
            for amp in AMPLITUDES:
                t0 = time.perf_counter()
                r = _run(name, seeds, common, local_field=amp)
                print(
                    f"{name:8s} {amp:8.2f} {r['before']:11.2f} {r['after']:6.2f} "
                    f"{-r['reduction']:+9.0%} {r['coarse_change']:+8.0%} "
                    f"{'/'.join(f'{x:g}' for x in r['spacings']):>22s} "
                    f"{time.perf_counter() - t0:4.0f}"
                )


if __name__ == "__main__":
    main()
