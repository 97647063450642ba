"""Blocks without GNSS/IMU adjusted from ``--start relative``: the convergence study.

The blocks of the table in docs/bundle-adjustment.md ("a block without start values"): FC300S,
FC6310 and ILCE-7RM2, 3 strips x 7 images, seeds 0-4; FC300S and ILCE-7RM2, 5 strips x 10
images, seeds 0-2; each with the start 5 m / 5 degrees, 20 m / 10 degrees and 50 m / 30
degrees off (63 blocks; the start values from relative orientations do not depend on that
start, the observations are the same). Start values as ``bundle adjust --start relative``
takes them (strips: the order of the images in the block's file, or ``--strips-by-line``:
one strip per flight line), then the adjustment with the calibration free from the nominal
camera. "truth": converged and every projection centre within 1 mm of the adjustment
started from the true values. One JSON line per block, then the count.

    python benchmarks/start_relative.py [--strips-by-line] [--quick]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import photogeom as pg
from photogeom.bundle import start_from_relative_orientation
from photogeom.cli.bundle import found_strips

OFFSETS = ((5.0, 5.0), (20.0, 10.0), (50.0, 30.0))


def cases(quick: bool) -> list[tuple[str, int, int, tuple[float, float], int]]:
    """(camera, strips, images per strip, (metres, degrees) off, seed) of every block."""
    out = []
    for cam in ("FC300S", "FC6310", "ILCE-7RM2"):
        for off in OFFSETS[:1] if quick else OFFSETS:
            out += [(cam, 3, 7, off, seed) for seed in range(2 if quick else 5)]
    for cam in ("FC300S", "ILCE-7RM2"):
        for off in OFFSETS[:1] if quick else OFFSETS:
            out += [(cam, 5, 10, off, seed) for seed in range(1 if quick else 3)]
    return out


def run(cam: str, strips: int, per: int, off, seed: int, by_line: bool) -> dict:
    """One block: start values, adjustment, comparison with the adjustment from the truth."""
    sim = pg.simulate.uav_block(
        cam,
        seed=seed,
        strips=strips,
        images_per_strip=per,
        gnss_sigma=None,
        imu_sigma_deg=None,
        initial_position_error=off[0],
        initial_attitude_error_deg=off[1],
    )
    b = sim.block
    tie = (b.role == "tie")[:, None]
    ref = pg.bundle_adjust(
        b.replace(exterior=sim.truth.exterior.copy(), xyz=np.where(tie, sim.truth.xyz, b.xyz))
    )
    ids = b.image_ids.tolist()
    lines = [ids[k * per : (k + 1) * per] for k in range(strips)] if by_line else found_strips(b)
    out: dict = {"camera": cam, "images": strips * per, "off": list(off), "seed": seed}
    t0 = time.perf_counter()
    try:
        new, st = start_from_relative_orientation(b, lines)
    except pg.PhotogeomError as exc:
        return {**out, "truth": False, "error": f"{type(exc).__name__}: {exc}"}
    out["start_s"] = round(time.perf_counter() - t0, 2)
    out["bridged"] = sum(len(m.bridged) for m in st.strips)
    fit = pg.bundle_adjust(new)
    d = float(np.max(np.linalg.norm(fit.block.exterior[:, :3] - ref.block.exterior[:, :3], axis=1)))
    out.update(
        truth=bool(fit.converged and d < 1e-3),
        iterations=fit.iterations,
        sigma0=round(float(fit.sigma0), 4),
        centres_off_m=d,
    )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strips-by-line", action="store_true", help="one strip per flight line")
    ap.add_argument("--quick", action="store_true", help="one offset, fewer seeds")
    args = ap.parse_args()
    rows = []
    for case in cases(args.quick):
        row = run(*case, by_line=args.strips_by_line)
        rows.append(row)
        print(json.dumps(row), flush=True)
    print(f"truth: {sum(r['truth'] for r in rows)} of {len(rows)}")


if __name__ == "__main__":
    main()
