"""Benchmark: frame-camera projection with Brown distortion and space resection vs OpenCV.

Measured in one run on the same machine, reported as ratios (photogeom time / OpenCV time):

1. projection of 1e6 and 1e7 ground points through an oriented camera with Brown distortion
   (K1-K3, P1, P2, affinity B1: the terms both models share): ``photogeom.project`` vs
   ``cv2.projectPoints``; the two results are also compared (max difference in pixels).
   Note: called from Python, ``cv2.projectPoints`` always fills its Jacobian output
   (2n x 15 values), which is part of its time; there is no Python call without it;
2. space resection of one image from n = 6, 20 and 100 control points:
   ``photogeom.space_resection`` (closed-form P3P start + Gauss-Markov adjustment with full
   statistics) vs ``cv2.solvePnP`` with ``SOLVEPNP_ITERATIVE`` (Levenberg-Marquardt on the same
   reprojection error, no statistics); also with start values given to both.

Run: ``python benchmarks/camera.py`` (a minute or two). Target: projection of 1e7 points
within 2x of OpenCV.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

import photogeom as pg

CALIB = pg.MetashapeCalibration(
    width=8000,
    height=6000,
    f=5600.0,
    cx=12.3,
    cy=-8.7,
    k1=-0.11,
    k2=0.12,
    k3=-0.04,
    p1=3e-4,
    p2=-2e-4,
    b1=0.6,
)
EO = pg.ExteriorOrientation.from_degrees(500.0, 300.0, 220.0, 12.0, -8.0, 70.0)
D = np.diag([1.0, -1.0, -1.0])  # photogrammetric camera axes -> OpenCV / Metashape axes


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def scene(n: int, rng: np.random.Generator) -> np.ndarray:
    xn = rng.uniform(-0.7, 0.55, (n, 2))
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(n)]) * rng.uniform(50, 400, (n, 1))
    return EO.position + pc @ EO.matrix


def opencv_pose(eo: pg.ExteriorOrientation):
    R = D @ eo.matrix
    rvec, _ = cv2.Rodrigues(R)
    return rvec, -R @ eo.position


def bench_projection(sizes, repeat: int) -> list[str]:
    io = CALIB.interior_orientation()
    K, dist = CALIB.to_opencv()
    rvec, tvec = opencv_pose(EO)
    rng = np.random.default_rng(0)
    lines = []
    for n in sizes:
        g = scene(n, rng)
        ours = pg.project(g, io, EO, system="pixel")
        theirs = cv2.projectPoints(g, rvec, tvec, K, dist)[0][:, 0]
        diff = float(np.max(np.abs(ours - theirs)))
        t_pg = best_of(lambda g=g: pg.project(g, io, EO, system="pixel"), repeat)
        t_cv = best_of(lambda g=g: cv2.projectPoints(g, rvec, tvec, K, dist), repeat)
        lines.append(
            f"projection n={n:>9,d}: photogeom {t_pg:7.3f} s, OpenCV {t_cv:7.3f} s, "
            f"ratio {t_pg / t_cv:5.2f}; max |difference| {diff:.1e} px"
        )
        del g, ours, theirs
    return lines


def _resection_case(n: int, io, K, rng, repeat: int) -> str:
    dist0 = np.zeros(5)
    rvec0, tvec0 = opencv_pose(EO)
    g = scene(n, rng)
    xy = pg.project(g, io, EO) + rng.normal(0, 0.3, (n, 2))
    pix = io.image_to_pixel(xy)
    fit = pg.space_resection(g, xy, io)
    _, rv, tv = cv2.solvePnP(g, pix, K, dist0, flags=cv2.SOLVEPNP_ITERATIVE)
    centre_cv = -cv2.Rodrigues(rv)[0].T @ tv.ravel()
    dpos = float(np.max(np.abs(centre_cv - fit.position)))

    def ours():
        pg.space_resection(g, xy, io)

    def ours_start():
        pg.space_resection(g, xy, io, initial=EO)

    def theirs():
        cv2.solvePnP(g, pix, K, dist0, flags=cv2.SOLVEPNP_ITERATIVE)

    def theirs_start():
        cv2.solvePnP(
            g,
            pix,
            K,
            dist0,
            rvec=rvec0.copy(),
            tvec=tvec0.reshape(3, 1).copy(),
            useExtrinsicGuess=True,
            flags=cv2.SOLVEPNP_ITERATIVE,
        )

    t_pg, t_cv = best_of(ours, repeat), best_of(theirs, repeat)
    t_pg0, t_cv0 = best_of(ours_start, repeat), best_of(theirs_start, repeat)
    return (
        f"resection n={n:>4d}: photogeom {1e3 * t_pg:7.2f} ms, OpenCV {1e3 * t_cv:6.2f} ms, "
        f"ratio {t_pg / t_cv:6.1f} | with start values: {1e3 * t_pg0:7.2f} ms vs "
        f"{1e3 * t_cv0:6.2f} ms, ratio {t_pg0 / t_cv0:6.1f} | centres differ by {dpos:.1e} m"
    )


def bench_resection(sizes, repeat: int) -> list[str]:
    io0 = CALIB.interior_orientation()
    io = pg.InteriorOrientation(
        io0.f, io0.x0, io0.y0, unit="px", b1=io0.b1, origin_px=io0.origin_px
    )
    K, _ = CALIB.to_opencv()
    rng = np.random.default_rng(1)
    return [_resection_case(n, io, K, rng, repeat) for n in sizes]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes (smoke test)")
    args = ap.parse_args()
    sizes = [100_000, 1_000_000] if args.quick else [1_000_000, 10_000_000]
    print(
        "photogeom", pg.__version__, "| OpenCV", cv2.__version__, "| threads", cv2.getNumThreads()
    )
    print("(cv2.projectPoints from Python also computes its 2n x 15 Jacobian)")
    for line in bench_projection(sizes, repeat=2 if args.quick else 3):
        print(line, flush=True)
    for line in bench_resection([6, 20, 100], repeat=5 if args.quick else 20):
        print(line, flush=True)


if __name__ == "__main__":
    main()
