"""Relative orientation and the block start: Monte Carlo, robustness, timing against OpenCV.

Run:  python benchmarks/relative_orientation.py            (about two minutes)
      python benchmarks/relative_orientation.py --quick    (200 trials)

A. Reported (a-priori) standard deviations of the five elements and of the model points
   (orientation uncertainty included) against the spread of 1000 noisy trials, for both
   parameterisations; mean sigma0.
B. Wrong matches (10-40 %): flagged, missed (wrong but on the epipolar line), false alarms,
   orientation error.
C. Time of one pair (120 points, 30 % wrong matches) against OpenCV's findEssentialMat +
   recoverPose on the same points (the start of ours), in one run.
D. Block start of a simulated 2-strip block (5 images per strip, opposite flight
   directions, 0.5 px noise, 3 % wrong matches): exterior-orientation errors against the truth.
E. The convergence basin: a bundle adjustment of that block (GTSAM's Levenberg-Marquardt,
   projection factors at 0.5 px, GCP priors at 1 cm; no wrong matches) started from our block
   start and from the truth reaches the same minimum (needs ``gtsam``, in ``.[bench]``).
"""

from __future__ import annotations

import argparse
import math
import time

import cv2
import numpy as np

import photogeom as pg

IO = pg.InteriorOrientation(100.0, unit="mm")


def pair(seed, n=30, bh=0.6, convergence=0.1, noise=0.0):
    rng = np.random.default_rng(seed)
    H = 100.0
    pts = np.column_stack(
        [rng.uniform(-35, 35 + bh * H, n), rng.uniform(-35, 35, n), rng.uniform(-15, 15, n)]
    )
    e1 = pg.ExteriorOrientation(0, 0, H, 0.01, -convergence, 0.02)
    e2 = pg.ExteriorOrientation(bh * H, 2.0, H + 1, -0.02, convergence, -0.01)
    xy1 = pg.project(pts, IO, e1) + rng.normal(0, noise, (n, 2))
    xy2 = pg.project(pts, IO, e2) + rng.normal(0, noise, (n, 2))
    return e1, e2, xy1, xy2


def table_a(trials: int) -> None:
    print(f"A. standard deviations against {trials} Monte-Carlo trials (sigma 0.004 mm)")
    sd = 0.004
    _, _, xy1, xy2 = pair(7)
    for method in ("dependent", "independent"):
        ref = pg.relative_orientation(xy1, xy2, IO, method=method, sigma=sd)
        mp = ref.model_points()
        rng = np.random.default_rng(1)
        P, X, S = [], [], []
        for _ in range(trials):
            a = xy1 + rng.normal(0, sd, xy1.shape)
            b = xy2 + rng.normal(0, sd, xy2.shape)
            f = pg.relative_orientation(a, b, IO, method=method, sigma=sd, robust=False)
            P.append(f.parameters)
            X.append(f.model_points().points)
            S.append(f.sigma0)
        ratio = np.std(P, axis=0, ddof=1) / np.array(list(ref.std_errors_prior.values()))
        pr = np.std(X, axis=0, ddof=1) / np.sqrt(np.einsum("nii->ni", mp.covariance_prior))
        print(
            f"  {method:12s} MC spread / reported std: "
            + ", ".join(f"{n} {r:.3f}" for n, r in zip(ref.parameter_names, ratio))
        )
        print(
            f"  {'':12s} model points X, Y, Z: median ratio "
            + ", ".join(f"{r:.3f}" for r in np.median(pr, axis=0))
            + f" (range {pr.min():.3f}-{pr.max():.3f}); mean sigma0 {np.mean(S):.3f}"
        )


def table_b() -> None:
    print("B. wrong matches (120 points, sigma 0.003 mm, 5 seeds each)")
    sd = 0.003
    for frac in (0.1, 0.2, 0.3, 0.4):
        flagged = missed = false = 0
        err = worst_missed = 0.0
        for seed in range(5):
            e1, e2, xy1, xy2 = pair(seed, n=120, noise=sd)
            rng = np.random.default_rng(seed + 100)
            wrong = rng.random(120) < frac
            xy2 = xy2.copy()
            xy2[wrong] += rng.uniform(-4, 4, (int(wrong.sum()), 2))
            f = pg.relative_orientation(xy1, xy2, IO, sigma=sd)
            flagged += int((f.flagged & wrong).sum())
            missed += int((~f.flagged & wrong).sum())
            if (~f.flagged & wrong).any():
                worst_missed = max(
                    worst_missed, float(np.abs(f.parallax[~f.flagged & wrong]).max())
                )
            false += int((f.flagged & ~wrong).sum())
            R = e2.matrix @ e1.matrix.T
            err = max(err, float(np.abs(f.pair.relative_rotation - R).max()))
        print(
            f"  {frac:.0%}: flagged {flagged}, missed {missed} (largest |py| "
            f"{worst_missed / sd:.1f} sigma), "
            f"false alarms {false}, max rotation error {err:.2e}"
        )


def table_c(rounds: int = 30) -> None:
    print("C. time of one pair (120 points, 30 % wrong matches)")
    _e1, _e2, xy1, xy2 = pair(3, n=120, noise=0.003)
    rng = np.random.default_rng(5)
    wrong = rng.random(120) < 0.3
    xy2 = xy2.copy()
    xy2[wrong] += rng.uniform(-4, 4, (int(wrong.sum()), 2))
    n1 = IO.normalized_from_image(xy1)
    n2 = IO.normalized_from_image(xy2)
    ours, cv = [], []
    for _ in range(rounds):
        t = time.perf_counter()
        pg.relative_orientation(xy1, xy2, IO, sigma=0.003)
        ours.append(time.perf_counter() - t)
        t = time.perf_counter()
        E, m = cv2.findEssentialMat(n1, n2, np.eye(3), method=cv2.RANSAC, threshold=1.5e-4)
        cv2.recoverPose(E[:3], n1, n2, np.eye(3), mask=m)
        cv.append(time.perf_counter() - t)
    mo, mc = np.median(ours), np.median(cv)
    print(
        f"  photogeom (start + adjustment + snooping) {mo * 1e3:.1f} ms; OpenCV "
        f"findEssentialMat + recoverPose {mc * 1e3:.2f} ms; ratio {mo / mc:.1f}"
    )


def simulate_block(seed=0, noise=0.5, n_points=600, wrong=0.03):
    rng = np.random.default_rng(seed)
    io = pg.InteriorOrientation(1000.0, unit="px")
    H = 100.0
    strips, truth = [], {}
    for s, (y, direction) in enumerate([(0.0, 1), (49.0, -1)]):
        xs = np.arange(5) * 40.0
        if direction < 0:
            xs = xs[::-1]
        ids = []
        for k, x in enumerate(xs):
            iid = f"{s + 1}{k + 1:02d}"
            ang = rng.normal(0, math.radians(2), 3)
            if direction < 0:
                ang[2] += math.pi
            truth[iid] = pg.ExteriorOrientation(x, y, H + rng.normal(0, 2), *ang)
            ids.append(iid)
        strips.append(ids)
    P = np.column_stack(
        [rng.uniform(-50, 210, n_points), rng.uniform(-35, 84, n_points), np.zeros(n_points)]
    )
    P[:, 2] = 5 * np.sin(P[:, 0] / 30) + 3 * np.cos(P[:, 1] / 20)
    pids = [f"p{i}" for i in range(n_points)]
    obs = {}
    for iid, e in truth.items():
        xy = pg.project(P, io, e)
        ok = (np.abs(xy[:, 0]) < 500) & (np.abs(xy[:, 1]) < 350)
        xy = xy + rng.normal(0, noise, xy.shape)
        bad = rng.random(len(P)) < wrong
        xy[bad] += rng.uniform(-60, 60, (int(bad.sum()), 2))
        obs[iid] = {pids[i]: xy[i] for i in np.flatnonzero(ok)}
    gcps = [(x, y) for x in (-5, 80, 165) for y in (-25, 25, 75)]
    control = {}
    for gx, gy in gcps:
        i = int(np.argmin(np.hypot(P[:, 0] - gx, P[:, 1] - gy)))
        control[pids[i]] = P[i]
    return io, strips, truth, obs, control, dict(zip(pids, P))


def table_d() -> None:
    print("D. block start: 2 strips x 5 images, H 100 m, 0.5 px, 3 % wrong matches")
    io, strips, truth, obs, control, _ = simulate_block()
    t = time.perf_counter()
    bs = pg.block_start(strips, {i: io for s in strips for i in s}, obs, control, sigma=0.5)
    el = time.perf_counter() - t
    dp, da = [], []
    for i, e in truth.items():
        f = bs.exteriors[i]
        dp.append(np.linalg.norm(f.position - e.position))
        R = f.matrix @ e.matrix.T
        da.append(math.degrees(math.acos(np.clip((np.trace(R) - 1) / 2, -1, 1))))
    print(
        f"  {el:.2f} s; projection centres: RMS {np.sqrt(np.mean(np.square(dp))):.3f} m, "
        f"max {max(dp):.3f} m; attitude: RMS {np.sqrt(np.mean(np.square(da))):.3f} deg, "
        f"max {max(da):.3f} deg"
    )


def gtsam_bundle(io, obs, start_eo, start_pts, control, sigma_px=0.5, sigma_gcp=0.01):
    """Bundle adjustment in GTSAM: poses camera -> world with OpenCV axes
    (``R_wc = M.T diag(1, -1, -1)``), measurements ``(x, -y)`` (principal point at 0)."""
    import gtsam
    from gtsam.symbol_shorthand import L, X

    F = np.diag([1.0, -1.0, -1.0])
    K = gtsam.Cal3_S2(io.f, io.f, 0.0, 0.0, 0.0)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    imgs = list(start_eo)
    pidx = {p: k for k, p in enumerate(start_pts)}
    noise = gtsam.noiseModel.Isotropic.Sigma(2, sigma_px)
    for i, iid in enumerate(imgs):
        for p, xy in obs[iid].items():
            if p in pidx:
                graph.add(
                    gtsam.GenericProjectionFactorCal3_S2(
                        gtsam.Point2(xy[0], -xy[1]), noise, X(i), L(pidx[p]), K
                    )
                )
        e = start_eo[iid]
        values.insert(X(i), gtsam.Pose3(gtsam.Rot3(e.matrix.T @ F), gtsam.Point3(*e.position)))
    gcp_noise = gtsam.noiseModel.Isotropic.Sigma(3, sigma_gcp)
    for p, k in pidx.items():
        values.insert(L(k), gtsam.Point3(*start_pts[p]))
        if p in control:
            graph.add(gtsam.PriorFactorPoint3(L(k), gtsam.Point3(*control[p]), gcp_noise))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    opt = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    res = opt.optimize()
    poses = {}
    for i, iid in enumerate(imgs):
        P = res.atPose3(X(i))
        poses[iid] = (np.array(P.translation()), np.array(P.rotation().matrix()))
    return poses, graph.error(res), opt.iterations()


def table_e() -> None:
    print("E. bundle adjustment (GTSAM) from the block start and from the truth")
    try:
        import gtsam  # noqa: F401
    except ImportError:
        print("  skipped: gtsam is not installed (pip install '.[bench]')")
        return
    io, strips, truth, obs, control, P = simulate_block(wrong=0.0)
    bs = pg.block_start(strips, {i: io for s in strips for i in s}, obs, control, sigma=0.5)
    pts = {p: x for p, x in bs.points.items() if sum(p in o for o in obs.values()) >= 2}
    ours, cost_ours, it_ours = gtsam_bundle(io, obs, bs.exteriors, pts, control)
    ref, cost_ref, it_ref = gtsam_bundle(io, obs, truth, {p: P[p] for p in pts}, control)
    dpos = max(np.linalg.norm(ours[i][0] - ref[i][0]) for i in ours)
    drot = max(np.abs(ours[i][1] - ref[i][1]).max() for i in ours)
    print(
        f"  {len(pts)} tie points; from the block start: cost {cost_ours:.6f}, {it_ours} "
        f"iterations; from the truth: cost {cost_ref:.6f}, {it_ref} iterations"
    )
    print(
        f"  same minimum: cost difference {abs(cost_ours - cost_ref) / cost_ref:.1e} "
        f"(relative), projection centres {dpos:.1e} m, rotation matrices {drot:.1e}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    table_a(200 if args.quick else 1000)
    table_b()
    table_c(10 if args.quick else 30)
    table_d()
    table_e()


if __name__ == "__main__":
    main()
