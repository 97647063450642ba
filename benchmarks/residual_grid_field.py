"""Benchmark: how well residual grids recover the simulator's true local field.

Per preset (small blocks): adjust with Brown self-calibration, fit grids to the tie-point
residuals, and compare them (a) with the true local field at the supported nodes
(:func:`photogeom.calibration.field_recovery`) and (b) with its visible part, the residuals
that a noise-free adjustment of the same block leaves (:func:`photogeom.calibration.
visible_field`, :func:`photogeom.calibration.visible_recovery`). Printed: RMS of the field,
share of it that is visible, and the RMS of the differences relative to each reference.

With ``--absorption`` also: which unknowns take the rest of the field up. The noise-free
adjustment of the truth is repeated with the tie points held, the orientations held, and
both (only the calibration free), and for each the visible share and the floor: the RMS of
the field that no method working on residuals can recover (visible part minus field),
over the field's RMS. ``--forward-overlap`` and ``--side-overlap`` change the geometry.

With ``--bound`` also the floor of every method, residual-based or not: the error of the
best estimator given the simulator's own field distribution
(:func:`photogeom.calibration.field_bound`), in expectation and for this block's field, and
the in-adjustment grids (500 px, temporal constraints 0.3 px, default amplitude) on the same
block for comparison.

Run: ``python benchmarks/residual_grid_field.py [--ties 1000] [--spacing 200]
[--absorption] [--bound]`` (about a minute per preset; ``--bound`` 15 s on 2 x 8 images,
minutes on 48).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import photogeom as pg


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", default="ILCE-7RM2,FC6310,FC300S")
    ap.add_argument("--spacing", type=float, default=200.0, help="px")
    ap.add_argument("--sigma-constraint", default="0.1", help="px, or vce")
    ap.add_argument("--ties", type=float, default=1000.0, help="tie points per image")
    ap.add_argument("--strips", type=int, default=2)
    ap.add_argument("--images", type=int, default=8, help="images per strip")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--forward-overlap", type=float, default=None)
    ap.add_argument("--side-overlap", type=float, default=None)
    ap.add_argument("--absorption", action="store_true", help="what takes the field up")
    ap.add_argument("--bound", action="store_true", help="the best estimator's error")
    a = ap.parse_args()
    sc = a.sigma_constraint if a.sigma_constraint == "vce" else float(a.sigma_constraint)
    print(
        f"load average {os.getloadavg()[0]:.1f}; spacing {a.spacing:g} px, sigma_constraint "
        f"{sc}, {a.strips} x {a.images} images, {a.ties:g} tie points per image"
    )
    print(
        f"{'preset':10s} {'field px':>8s} {'visible share':>13s} {'diff/true field':>15s} "
        f"{'diff/visible':>12s}"
    )
    for name in a.presets.split(","):
        sim = pg.simulate.uav_block(
            name,
            seed=a.seed,
            strips=a.strips,
            images_per_strip=a.images,
            tie_points_per_image=a.ties,
            forward_overlap=a.forward_overlap,
            side_overlap=a.side_overlap,
        )
        fit = pg.bundle_adjust(sim.block, snooping=False)
        grids = pg.calibration.fit_residual_grids(
            fit.block, a.spacing, sigma_constraint=sc, folds=0
        )
        true = pg.calibration.field_recovery(sim, grids)["block"]
        visible = pg.calibration.visible_field(sim)
        vis = pg.calibration.visible_recovery(sim, grids, visible)
        print(
            f"{name:10s} {vis['field_rms']:8.3f} {vis['visible_share']:13.2f} "
            f"{true['ratio']:15.2f} {vis['ratio']:12.2f}"
        )
        if a.absorption:
            absorption(sim, visible)
        if a.bound:
            bound(sim, fit)


def _rms(v) -> float:
    """RMS length of (n, 2) vectors."""
    return float(np.sqrt(np.mean(np.sum(v**2, axis=1))))


def absorption(sim, visible) -> None:
    """Visible share and floor with nothing (``visible``, :func:`visible_field` of ``sim``),
    the tie points, the orientations or both held."""
    b = sim.block
    rows = np.flatnonzero(b.role[b.obs_point] == "tie")
    field = sim.local[rows]
    rays = np.bincount(b.obs_point[rows])
    print(f"{'':10s} mean rays per tie point {rays[rays > 0].mean():.1f}")
    cases = (
        ("nothing held (as above)", None),
        ("tie points held", {"hold_points": True}),
        ("orientations held", {"fix_exterior": True}),
        ("both held (calibration free)", {"hold_points": True, "fix_exterior": True}),
    )
    for label, kw in cases:
        v = (visible if kw is None else pg.calibration.visible_field(sim, **kw))[rows]
        share, floor = _rms(v) / _rms(field), _rms(v + field) / _rms(field)
        print(f"{'':10s} {label:30s} visible share {share:5.2f}  floor {floor:5.2f}")


def bound(sim, fit) -> None:
    """The best estimator's error against the in-adjustment grids on the same block."""
    t0 = time.perf_counter()
    b = pg.calibration.field_bound(sim)
    t_b = time.perf_counter() - t0
    ga = pg.calibration.adjust_with_grids(
        fit.block, 500.0, sigma_constraint=1.0, sigma_temporal=0.3, std=False
    )
    ratio = pg.calibration.field_recovery(sim, ga.grids)["block"]["ratio"]
    print(
        f"{'':10s} best estimator (simulator's prior): error/field {b['expected_ratio']:.2f} "
        f"expected, {b['ratio']:.2f} on this block ({b['coefficients']} coefficients, "
        f"{t_b:.0f} s); grids in the adjustment (500 px): {ratio:.2f}"
    )


if __name__ == "__main__":
    main()
