"""Worked example of the bundle adjustment with self-calibration on a simulated UAV block.

* ``bundle-uav`` - a small FC300S block (2 strips of 6 images, GNSS/IMU, five control and four
  check points, one blunder of 50 px, no image-variant local distortion) adjusted with f, cx,
  cy, K1-K3, P1, P2 free. The w-test of the first adjustment names the blunder by image and
  point id; that observation is removed and the block adjusted again, and the estimate is
  compared with the simulator's truth (calibration errors in standard deviations,
  projection-centre errors, check points).
"""

from __future__ import annotations

import numpy as np

from . import Example

FREE = ("f", "cx", "cy", "k1", "k2", "k3", "p1", "p2")


def _truth_rows(sim, fit) -> tuple[list[list], dict]:
    """Calibration estimate vs truth, in units and in standard deviations."""
    g = next(iter(fit.calibration))
    rows = []
    worst = 0.0
    for n in FREE:
        est, std = fit.calibration[g][n], fit.calibration_std[g][n]
        true = float(getattr(sim.camera, n))
        z = (est - true) / std
        worst = max(worst, abs(z))
        rows.append([n, est, true, est - true, std, z])
    b, t = fit.block, sim.truth
    dC = b.exterior[:, :3] - t.exterior[:, :3]
    zC = dC / fit.exterior_std[:, :3]
    info = {
        "worst_z": worst,
        "centre_rms": np.sqrt(np.mean(dC**2, axis=0)),
        "centre_z_rms": float(np.sqrt(np.mean(zC**2))),
    }
    return rows, info


def _uav(report) -> str:
    from .. import bundle, simulate
    from ..bundle.result import CAL_UNITS, _cal_number

    sim = simulate.uav_block(
        "FC300S",
        seed=7,
        strips=2,
        images_per_strip=6,
        tie_points_per_image=100,
        blunders=1,
        blunder_size=50.0,
        local_field=0.0,
    )
    first = bundle.bundle_adjust(sim.block, free=FREE)
    o = sim.block.observations
    r = int(sim.blunder_rows[0])
    blunder = (o.image_ids[r].item(), o.point_ids[r].item())
    flagged = first.snooping["flagged"]
    found = bool(flagged) and tuple(flagged[0][:2]) == blunder
    # remove the observation with the largest |w| and adjust again
    img, pt, wmax = flagged[0] if flagged else (None, None, float("nan"))
    keep = ~((o.image_ids == img) & (o.point_ids == pt))
    fit = bundle.bundle_adjust(
        sim.block.select_observations(keep), free=FREE, point_covariance=True
    )
    rows, info = _truth_rows(sim, fit)
    first_line = (
        f"first adjustment: sigma0 {first.sigma0:.3f}, {len(flagged)} observation(s) fail the "
        f"w-test, the largest |w| = {wmax:.1f} at image {img}, point {pt} "
        f"({'the simulated blunder' if found else 'NOT the simulated blunder'}); removed, "
        "adjusted again:"
    )
    lines = [
        sim.summary(),
        "",
        first_line,
        "",
        fit.summary(),
        "",
        "against the simulator's truth (px; distortion dimensionless):",
        f"  {'parameter':<9}{'estimate':>17}{'true':>17}{'estimate - true':>17}"
        f"{'std. dev.':>15}{'in std. dev.':>14}  unit",
        *[
            f"  {n:<9}{_cal_number(e, CAL_UNITS[n]):>17}{_cal_number(t, CAL_UNITS[n]):>17}"
            f"{_cal_number(d, CAL_UNITS[n]):>17}{_cal_number(s, CAL_UNITS[n]):>15}"
            f"{z:>+14.2f}  {CAL_UNITS[n]}"
            for n, e, t, d, s, z in rows
        ],
        f"  projection centres: RMS error X {info['centre_rms'][0]:.4f}, Y "
        f"{info['centre_rms'][1]:.4f}, Z {info['centre_rms'][2]:.4f} m "
        f"({info['centre_z_rms']:.2f} sigma RMS)",
    ]
    if report is not None:
        from ..report.bundle import add_bundle_fit
        from ..report.format import fmt_std, fmt_value

        report.add_text("The block", sim.summary(), pre=True)
        report.add_text(
            None,
            "Simulated by pg.simulate.uav_block('FC300S', seed=7, strips=2, images_per_strip=6, "
            "tie_points_per_image=100, blunders=1, local_field=0): without the image-variant "
            "local distortion the camera model is complete, so the estimate should differ from "
            "the truth by about its standard deviations. Adjusted by pg.bundle_adjust(block, "
            "free=('f', 'cx', 'cy', 'k1', 'k2', 'k3', 'p1', 'p2')).\n\n"
            + first_line.replace(
                "adjusted again:",
                "adjusted again with point_covariance=True (the report below).",
            ),
            pre=False,
        )
        report.add_table(
            "Calibration against the truth",
            ["parameter", "estimate", "true", "estimate - true", "std. dev.", "in std. dev."],
            [
                [n, fmt_value(e, s), f"{t:g}", f"{d:.3g}", fmt_std(s), f"{z:+.2f}"]
                for n, e, t, d, s, z in rows
            ],
            note="f, cx, cy in px; K, P dimensionless; differences within about two standard "
            "deviations are what the noise explains",
        )
        add_bundle_fit(report, fit, "FC300S block")
    return "\n".join(lines)


EXAMPLES = [
    Example(
        "bundle-uav",
        "Bundle adjustment with self-calibration: simulated FC300S UAV block with a blunder",
        _uav,
    ),
]
