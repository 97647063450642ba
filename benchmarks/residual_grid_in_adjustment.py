"""Benchmark: residual grids after the adjustment (the study) against grids inside it.

For each preset of the simulator (small blocks, or the study's sizes): one Brown
self-calibrating adjustment, then (a) the post-processing of the study - grids fitted to
the residuals, observations corrected, re-adjusted with orientation and calibration
fixed - (b) the grids estimated inside the adjustment
(:func:`photogeom.calibration.adjust_with_grids`, per image, with
temporal constraints unless ``--no-temporal`` and the amplitude from the residuals
unless ``--sigma-amplitude`` says otherwise), and (c) both: (b) post-processed with
300 px grids. Printed per method: the fitted field against the true local field and
against its visible part (what the residuals of an adjustment can show,
:func:`photogeom.calibration.visible_field`), check-point RMSE (GSD), the RMSE of every
tie point against its truth (GSD; thousands of points where the block has a few check
points), the mean height step between consecutive stereo models (GSD), the tie-point
residual RMS and the time (the
first adjustment included); then the step and the tie-point RMSE again with the
observations measured anew (``sim.rematch``, the same fresh noise for every method), so
that no method is credited with the noise its grids fitted.

Run: ``python benchmarks/residual_grid_in_adjustment.py`` (about half a minute on an idle
2-core machine; the in-adjustment time grows with the cube of images x nodes on small,
fully connected blocks), or ``--size study --spacing 1000`` for the study's blocks (250 /
195 / 82 images; a few minutes; 500 px grids there take 1-2 minutes per iteration and
2.4 GB on ILCE-7RM2, see ``residual_grid_in_adjustment_memory.py``).
"""

from __future__ import annotations

import argparse
import os

import photogeom as pg


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", default="ILCE-7RM2,FC6310,FC300S")
    ap.add_argument("--spacing", type=float, default=500.0, help="grid spacing, px")
    ap.add_argument("--sigma-constraint", type=float, default=1.0, help="px")
    ap.add_argument("--sigma-temporal", type=float, default=0.3, help="px")
    ap.add_argument("--no-temporal", action="store_true")
    ap.add_argument(
        "--sigma-amplitude",
        default="residuals",
        help="px, 'residuals' (the tie-point residuals' RMS) or 'none'",
    )
    ap.add_argument("--size", choices=("small", "study"), default="small")
    ap.add_argument("--strips", type=int, default=2)
    ap.add_argument("--images", type=int, default=8, help="images per strip (small size)")
    ap.add_argument("--ties", type=float, default=300.0, help="tie points per image")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--per", choices=("image", "camera"), default="image")
    ap.add_argument(
        "--static",
        type=float,
        default=0.0,
        help="share of the field common to all images (1: a static sensor distortion)",
    )
    a = ap.parse_args()
    st = None if a.no_temporal or a.per == "camera" else a.sigma_temporal
    sa = {"none": None, "residuals": "residuals"}.get(a.sigma_amplitude)
    sa = float(a.sigma_amplitude) if sa is None and a.sigma_amplitude != "none" else sa
    print(
        f"load average {os.getloadavg()[0]:.1f}; spacing {a.spacing:g} px, sigma_constraint "
        f"{a.sigma_constraint:g} px, sigma_temporal {st} px, sigma_amplitude {sa}, "
        f"{'study size' if a.size == 'study' else f'{a.strips} x {a.images} images'}, "
        f"{a.ties:g} tie points per image, grids per {a.per}, static share {a.static:g}"
    )
    head = (
        f"{'preset':10s} {'method':14s} {'field/true':>10s} {'field/vis':>9s} "
        f"{'check X,Y,Z (GSD)':>20s} {'ties X,Y,Z (GSD)':>20s} {'step':>6s} {'res px':>7s} "
        f"{'time s':>7s} {'re-matched: step':>16s} {'ties X,Y,Z (GSD)':>20s}"
    )
    print(head)
    for name in a.presets.split(","):
        kw = {} if a.size == "study" else {"strips": a.strips, "images_per_strip": a.images}
        sim = pg.simulate.uav_block(
            name,
            seed=a.seed,
            size=a.size,
            **kw,
            tie_points_per_image=a.ties,
            local_field_static=a.static,
        )
        r = pg.calibration.compare_in_adjustment(
            sim,
            a.spacing,
            sigma_constraint=a.sigma_constraint,
            sigma_temporal=st,
            sigma_amplitude=sa,
            per=a.per,
        )
        b = r["before"]
        print(f"{name:10s} {r['images']} images")
        c = ", ".join(f"{x:.2f}" for x in b["check_rmse_gsd"])
        t = ", ".join(f"{x:.2f}" for x in b["tie_rmse_gsd"])
        print(
            f"{name:10s} {'adjustment':14s} {'':>10s} {'':>9s} {c:>20s} {t:>20s} "
            f"{b['mean_step']:6.2f}"
        )
        for m in ("post_hoc", "in_adjustment", "combined"):
            x = r[m]
            c = ", ".join(f"{v:.2f}" for v in x["check_rmse_gsd"])
            t = ", ".join(f"{v:.2f}" for v in x["tie_rmse_gsd"])
            tr = ", ".join(f"{v:.2f}" for v in x["tie_rmse_gsd_rematched"])
            print(
                f"{'':10s} {m:14s} {x['field']:10.2f} {x['visible']:9.2f} {c:>20s} {t:>20s} "
                f"{x['mean_step']:6.2f} {x['residual_rms']:7.3f} {x['seconds']:7.1f} "
                f"{x['mean_step_rematched']:16.2f} {tr:>20s}"
            )
        print(f"{'':10s} visible share of the true field (RMS): {r['visible_share']:.2f}")


if __name__ == "__main__":
    main()
