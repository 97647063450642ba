"""Monte-Carlo check of the bundle adjustment's statistics on a simulated block.

Each trial draws new image noise, new surveyed coordinates of the control and check points
and new GNSS/IMU observations (all with their standard deviations), adjusts the same block from the
same start, and records the calibration, one image's exterior orientation, the tie points
and the check points.
Printed: the ratio of the Monte-Carlo spread to the mean reported standard deviation (1 is
right; the sampling error of a spread from N trials is about 1/sqrt(2N)), the mean sigma0^2
(1 is right), the share of trials passing the global test at 5 % (0.95 is right), and for
a second experiment with wrong a-priori sigmas the variance components against the true
sigmas.

    python benchmarks/bundle_montecarlo.py [--trials 400] [--preset FC300S] [--loss huber]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import photogeom as pg


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=400)
    ap.add_argument("--preset", default="FC300S")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--loss", default="squared", help="squared, huber or cauchy")
    a = ap.parse_args()
    sim = pg.simulate.uav_block(a.preset, seed=a.seed, local_field=0.0, sigma=0.5)
    truth, start = sim.truth, sim.block
    ideal = truth.observations.uv
    known = truth.role != "tie"
    checks = np.flatnonzero(truth.role == "check")
    sig = truth.observations.sigma
    gid = truth.camera_ids[0].item()
    ties = np.flatnonzero(truth.role == "tie")
    tie = int(ties[0])
    img = 3
    names = ["f", "cx", "cy", "k1", "p1"]
    est, std, s02, pts, pstd, cpts, cstd, passed = [], [], [], [], [], [], [], []
    t0 = time.perf_counter()
    for k in range(a.trials):
        rng = np.random.default_rng(10_000 + k)
        uv = ideal + rng.normal(0.0, 1.0, ideal.shape) * sig[:, None]
        xyz = start.xyz.copy()
        xyz[known] = truth.xyz[known] + rng.normal(0.0, 1.0, (int(known.sum()), 3)) * (
            truth.point_sigma[known]
        )
        gn = truth.exterior[:, :3] + rng.normal(0, 1, (truth.n_images, 3)) * start.gnss_sigma
        imu = truth.exterior[:, 3:] + rng.normal(0, 1, (truth.n_images, 3)) * start.imu_sigma
        b = start.with_observations(uv=uv).replace(xyz=xyz, gnss=gn, imu=imu)
        r = pg.bundle_adjust(b, snooping=False, point_covariance=True, loss=a.loss)
        c, cs = r.calibration[gid], r.calibration_std[gid]
        est.append([c[n] for n in names] + list(r.block.exterior[img]) + list(r.block.xyz[tie]))
        std.append([cs[n] for n in names] + list(r.exterior_std[img]) + list(r.point_std[tie]))
        s02.append(r.sigma0**2)
        passed.append(bool(r.chi2["passed"]))
        pts.append(r.block.xyz[ties])
        pstd.append(r.point_std[ties])
        cpts.append(r.block.xyz[checks])
        cstd.append(r.point_std[checks])
    dt = time.perf_counter() - t0
    labels = [*names, "X0", "Y0", "Z0", "omega", "phi", "kappa", "X", "Y", "Z"]
    ratio = np.std(est, axis=0, ddof=1) / np.mean(std, axis=0)
    print(f"{a.trials} trials of a {truth.n_images}-image {a.preset} block, {dt:.0f} s")
    print(f"expected sampling error of each ratio: {1 / np.sqrt(2 * a.trials):.3f}")
    for n, q in zip(labels, ratio):
        print(f"  spread / reported std  {n:>6}: {q:.3f}")
    pr = np.std(pts, axis=0, ddof=1) / np.mean(pstd, axis=0)
    print(
        f"all {ties.size} tie points, spread / reported std: mean X {pr[:, 0].mean():.3f}, "
        f"Y {pr[:, 1].mean():.3f}, Z {pr[:, 2].mean():.3f} (one point's ratio scatters by "
        f"about {1 / np.sqrt(2 * a.trials):.3f})"
    )
    if checks.size:
        cr = np.std(cpts, axis=0, ddof=1) / np.mean(cstd, axis=0)
        print(
            f"{checks.size} check points (triangulated with the adjusted cameras), spread / "
            f"reported std: mean X {cr[:, 0].mean():.3f}, Y {cr[:, 1].mean():.3f}, "
            f"Z {cr[:, 2].mean():.3f}"
        )
    print(
        f"loss {a.loss}: mean sigma0^2 {np.mean(s02):.4f}; global test passed in "
        f"{np.mean(passed):.1%} of the trials (sampling error {np.sqrt(0.0475 / a.trials):.1%})"
    )
    # variance components: true tie sigma 0.8 px and GNSS 0.02 m against a-priori 0.5 / 0.05
    rng = np.random.default_rng(1)
    uv = ideal + rng.normal(0.0, 0.8, ideal.shape)
    gn = truth.exterior[:, :3] + rng.normal(0, 0.02, (truth.n_images, 3))
    b = start.with_observations(uv=uv, sigma=0.5).replace(
        gnss=gn, gnss_sigma=np.full((truth.n_images, 3), 0.05)
    )
    r = pg.bundle_adjust(b, variance_components=True, snooping=False)
    f = r.variance_components["factors"]
    print("variance components (estimated sigma; true in brackets):")
    print(f"  image observations: {0.5 * f.get('image_tie', np.nan):.3f} px (0.8)")
    if "gnss" in f:
        print(f"  GNSS positions:     {0.05 * f['gnss']:.4f} m (0.02)")


if __name__ == "__main__":
    main()
