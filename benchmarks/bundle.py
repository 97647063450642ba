"""Bundle adjustment benchmark: photogeom against pycolmap (Ceres) and GTSAM, same blocks.

Run:  python benchmarks/bundle.py                      (50, 250 and 2000 images)
      python benchmarks/bundle.py --sizes 50 250       (a subset)
      python benchmarks/bundle.py --quick              (one small block, a smoke run)
      python benchmarks/bundle.py --sizes 2000 --runs 0 1 3   (some solvers only; --help)

The blocks are simulated UAV blocks (``pg.simulate.uav_block``, FC300S camera) on the
camera model all three solvers share: f, B1 (OpenCV's fx = f + B1, fy = f), cx, cy, K1, K2,
P1, P2 (OpenCV's p2, p1); GTSAM's Cal3DS2 also has B2 (its skew ``s``), which is free in
its run and in photogeom's run against it. No control points, GNSS or IMU: the
solvers minimise the same cost, 0.5 * sum of squared pixel residuals (every observation
sigma 1 px), in a free network. Every solver starts from the same values: the truth
perturbed by the simulator (positions by 1 m, attitudes by 0.5 deg, the nominal camera
without distortion), tie points triangulated from that start, seen in three images or more.
(From the simulator's default start, 5 m and 2 deg off, GTSAM moved a tie point seen in
two images behind both cameras, where its projection factor stops contributing to the cost:
a lower cost that is not a minimum of the reprojection error. Every solver's result is
checked here for points behind cameras.)

Gauges: photogeom ``datum="free"`` (minimal constraints inside, the covariances reported
in the inner-constraint datum); pycolmap ``BundleAdjustmentGauge.TWO_CAMS_FROM_WORLD`` (the
first camera fixed and the second camera's position constrained on a sphere about it);
GTSAM a prior on the first pose (sigma 1e-3, rad and m) and a ``RangeFactorPose3`` between
the first and the farthest camera at their starting distance (sigma 1e-3 m). All three only
remove the seven gauge freedoms: the priors are met exactly at the minimum, which therefore
has the same reprojection cost.

Each solver runs in its own subprocess (peak memory ``ru_maxrss`` of that process, which
includes the interpreter, the libraries and the block itself) with one BLAS / solver
thread. Timed: the solve from the built problem to convergence (photogeom: the problem set-up
and the Levenberg-Marquardt loop; pycolmap: ``BundleAdjuster.solve``; GTSAM:
``LevenbergMarquardtOptimizer.optimize``), the peers' problem building separately. The
final cost of every solver is recomputed by photogeom from the solver's parameters, read
back through the conversions. photogeom's statistics are timed separately: the final
statistics pass with the exterior/calibration covariances only, with all point covariances
(``point_covariance=True``), and with data snooping (``snooping=True``: redundancy numbers and
w-tests of every observation).

Convergence: the same tolerance on the relative decrease of the cost for all three
(``--ftol``, default 1e-10: photogeom ``ftol``, Ceres ``function_tolerance`` with the
gradient and parameter tolerances off, GTSAM ``relativeErrorTol``).
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

#: The camera model the three solvers share (photogeom names).
SHARED = ("f", "cx", "cy", "k1", "k2", "p1", "p2", "b1")
#: GTSAM's Cal3DS2 adds the skew, photogeom's b2.
SHARED_GTSAM = (*SHARED, "b2")
#: images -> (strips, images per strip, tie points per image)
LAYOUTS = {
    21: (3, 7, 120),
    50: (5, 10, 250),
    250: (10, 25, 400),
    2000: (40, 50, 500),
}
D = np.diag([1.0, -1.0, -1.0])  # photogrammetric image axes <-> camera axes (z forward)


def simulate(n_images: int, seed: int = 1):
    """The block of ``n_images`` images (observation sigmas 1 px) and its truth."""
    import photogeom as pg

    strips, per_strip, tie = LAYOUTS[n_images]
    sim = pg.simulate.uav_block(
        "FC300S",
        seed=seed,
        strips=strips,
        images_per_strip=per_strip,
        tie_points_per_image=tie,
        gcps="none",
        checks=0,
        gnss_sigma=None,
        imu_sigma_deg=None,
        initial_position_error=1.0,
        initial_attitude_error_deg=0.5,
        brown={"k3": 0.0, "b2": 0.0},
        local_field=0.0,
        min_rays=3,
    )
    return sim.block.with_observations(sigma=1.0), sim.truth


def half_sum_squares(block) -> tuple[float, int]:
    """0.5 sum of squared pixel residuals and the number of observations behind a camera."""
    from photogeom.bundle import reprojection_residuals

    r = reprojection_residuals(block, behind="nan")
    return 0.5 * float(np.nansum(r**2)), int(np.isnan(r[:, 0]).sum())


# --- GTSAM -----------------------------------------------------------------------------------


def cal3ds2(c):
    """GTSAM ``Cal3DS2`` of a Metashape calibration (pixel origin: first pixel's centre)."""
    import gtsam

    return gtsam.Cal3DS2(
        c.f + c.b1,
        c.f,
        c.b2,
        c.width / 2 - 0.5 + c.cx,
        c.height / 2 - 0.5 + c.cy,
        c.k1,
        c.k2,
        c.p2,
        c.p1,
    )


def from_cal3ds2(k, c):
    """The Metashape calibration of a GTSAM ``Cal3DS2`` (``c`` gives the image size)."""
    fx, fy, s, u0, v0, k1, k2, p1, p2 = k.vector()
    return replace(
        c,
        f=fy,
        b1=fx - fy,
        b2=s,
        cx=u0 - c.width / 2 + 0.5,
        cy=v0 - c.height / 2 + 0.5,
        k1=k1,
        k2=k2,
        p1=p2,
        p2=p1,
    )


def gtsam_pose(C, M):
    """GTSAM ``Pose3`` (camera to world, camera z forward) of a centre and ``M``."""
    import gtsam

    return gtsam.Pose3(gtsam.Rot3(M.T @ D), np.asarray(C, dtype=float))


def gtsam_graph(block, *, sigmas: bool = False):
    """Factor graph (one ``GeneralSFMFactor2Cal3DS2`` per observation, shared calibration
    K0, poses X_i, points L_j) and the initial values of a one-camera block. ``sigmas``:
    the observations' sigmas as noise models (else unit)."""
    import gtsam
    from gtsam.symbol_shorthand import K, L, X

    g = gtsam.NonlinearFactorGraph()
    v = gtsam.Values()
    Ms = block.rotations()
    for i in range(block.n_images):
        v.insert(X(i), gtsam_pose(block.exterior[i, :3], Ms[i]))
    adj = block.role != "check"
    for j in np.flatnonzero(adj):
        v.insert(L(int(j)), block.xyz[j])
    v.insert(K(0), cal3ds2(block.calibrations[0]))
    o = block.observations
    unit = gtsam.noiseModel.Unit.Create(2)
    for r in np.flatnonzero(adj[block.obs_point]).tolist():
        nm = gtsam.noiseModel.Isotropic.Sigma(2, float(o.sigma[r])) if sigmas else unit
        g.add(
            gtsam.GeneralSFMFactor2Cal3DS2(
                o.uv[r], nm, X(int(block.obs_image[r])), L(int(block.obs_point[r])), K(0)
            )
        )
    return g, v


def gtsam_gauge(g, block, sigma: float = 1e-3) -> None:
    """Priors that fix exactly the seven gauge freedoms: the first pose (6) and the distance
    from the first to the farthest projection centre (scale), both at their start values."""
    import gtsam
    from gtsam.symbol_shorthand import X

    C = block.exterior[:, :3]
    far = int(np.argmax(np.linalg.norm(C - C[0], axis=1)))
    g.add(
        gtsam.PriorFactorPose3(
            X(0), gtsam_pose(C[0], block.rotations()[0]), gtsam.noiseModel.Isotropic.Sigma(6, sigma)
        )
    )
    g.add(
        gtsam.RangeFactorPose3(
            X(0),
            X(far),
            float(np.linalg.norm(C[far] - C[0])),
            gtsam.noiseModel.Isotropic.Sigma(1, sigma),
        )
    )


def block_from_gtsam(block, values):
    """The block with GTSAM's poses, points and calibration."""
    from gtsam.symbol_shorthand import K, L, X

    from photogeom.rotation import opk_from_matrix

    ext = block.exterior.copy()
    for i in range(block.n_images):
        P = values.atPose3(X(i))
        ext[i, :3] = P.translation()
        ext[i, 3:] = opk_from_matrix((P.rotation().matrix() @ D).T)
    xyz = block.xyz.copy()
    for j in np.flatnonzero(block.role != "check"):
        xyz[j] = values.atPoint3(L(int(j)))
    cal = from_cal3ds2(values.atCal3DS2(K(0)), block.calibrations[0])
    return block.replace(exterior=ext, xyz=xyz, calibrations=(cal,))


# --- workers (one per subprocess) ------------------------------------------------------------


def _calibration(block) -> dict:
    c = block.calibrations[0]
    return {n: float(getattr(c, n)) for n in SHARED_GTSAM}


def work_ours(block, args) -> dict:
    from photogeom.bundle.adjustment import Problem, levenberg_marquardt
    from photogeom.bundle.options import BundleOptions
    from photogeom.bundle.result import build_result

    free = SHARED_GTSAM if args.model == "gtsam" else SHARED
    opts = BundleOptions(
        datum="free",
        free=free,
        ftol=args.ftol,
        snooping=args.stats == "snooping",
        point_covariance=args.stats == "points",
    ).validate()
    block.validate()
    t0 = time.perf_counter()
    problem = Problem(block, opts)
    run = levenberg_marquardt(problem, problem.initial_state(), opts)
    t1 = time.perf_counter()
    fit = build_result(problem, run, opts, None, t1 - t0)
    t2 = time.perf_counter()
    cost, behind = half_sum_squares(fit.block)
    return {
        "time": t1 - t0,
        "stats_time": t2 - t1,
        "iterations": run.iterations,
        "converged": run.converged,
        "message": run.message,
        "cost": cost,
        "behind": behind,
        "calibration": _calibration(fit.block),
        "calibration_std": {n: fit.calibration_std[block.camera_ids[0].item()][n] for n in free},
    }


def work_pycolmap(block, args) -> dict:
    import pycolmap

    from photogeom.bundle import read_colmap, write_colmap

    with tempfile.TemporaryDirectory() as tmp:
        write_colmap(block, tmp, model="OPENCV")
        t0 = time.perf_counter()
        rec = pycolmap.Reconstruction(tmp)
        opts = pycolmap.BundleAdjustmentOptions()
        opts.print_summary = False
        opts.refine_focal_length = True
        opts.refine_principal_point = True
        opts.refine_extra_params = True
        so = opts.ceres.solver_options
        so.function_tolerance = args.ftol
        so.gradient_tolerance = 1e-30
        so.parameter_tolerance = 1e-30
        so.max_num_iterations = 200
        so.num_threads = 1
        config = pycolmap.BundleAdjustmentConfig()
        for image_id in sorted(rec.reg_image_ids()):
            config.add_image(image_id)
        config.fix_gauge(pycolmap.BundleAdjustmentGauge.TWO_CAMS_FROM_WORLD)
        adjuster = pycolmap.create_default_bundle_adjuster(opts, config, rec)
        t1 = time.perf_counter()
        summary = adjuster.solve()
        t2 = time.perf_counter()
        cs = summary.ceres_summary
        rec.write_text(tmp)
        back = read_colmap(tmp, image_key="id")
    cost, behind = half_sum_squares(back)
    return {
        "time": t2 - t1,
        "setup_time": t1 - t0,
        "iterations": int(cs.num_successful_steps + cs.num_unsuccessful_steps),
        "converged": str(summary.termination_type),
        "message": cs.message,
        "cost": cost,
        "behind": behind,
        "solver_cost": float(cs.final_cost),
        "calibration": _calibration(back),
    }


def work_gtsam(block, args) -> dict:
    import gtsam

    t0 = time.perf_counter()
    g, v = gtsam_graph(block)
    gtsam_gauge(g, block)
    p = gtsam.LevenbergMarquardtParams()
    p.setRelativeErrorTol(args.ftol)
    p.setAbsoluteErrorTol(0.0)
    p.setMaxIterations(200)
    opt = gtsam.LevenbergMarquardtOptimizer(g, v, p)
    t1 = time.perf_counter()
    res = opt.optimize()
    t2 = time.perf_counter()
    back = block_from_gtsam(block, res)
    cost, behind = half_sum_squares(back)
    return {
        "time": t2 - t1,
        "setup_time": t1 - t0,
        "iterations": int(opt.iterations()),
        "converged": True,
        "message": "",
        "cost": cost,
        "behind": behind,
        "solver_cost": float(g.error(res)),
        "calibration": _calibration(back),
    }


WORKERS = {"ours": work_ours, "pycolmap": work_pycolmap, "gtsam": work_gtsam}


def worker_main(args) -> None:
    with open(args.block, "rb") as fh:
        block = pickle.load(fh)
    out = WORKERS[args.worker](block, args)
    ru = resource.getrusage(resource.RUSAGE_SELF)
    out["maxrss_mb"] = ru.ru_maxrss / 1024.0
    out["process_cpu_s"] = ru.ru_utime + ru.ru_stime  # whole process, for a loaded machine
    print("RESULT " + json.dumps(out))


# --- driver ----------------------------------------------------------------------------------


def spawn(block_path: str, worker: str, ftol: float, *, model="colmap", stats="none", timeout):
    env = dict(os.environ)
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env[k] = "1"
    src = str(Path(__file__).resolve().parents[1] / "src")
    env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, __file__, "--worker", worker, "--block", block_path]
    cmd += ["--ftol", repr(ftol), "--model", model, "--stats", stats]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout} s"}
    for line in p.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    return {"error": (p.stderr or p.stdout).strip().splitlines()[-1:]}


def fmt_t(t):
    return "-" if t is None else (f"{t * 1e3:.0f} ms" if t < 1 else f"{t:.2f} s")


RUNS = {
    "ours (OPENCV set)": ("ours", "colmap", "none"),
    "pycolmap OPENCV": ("pycolmap", "colmap", "none"),
    "ours (Cal3DS2 set)": ("ours", "gtsam", "none"),
    "GTSAM Cal3DS2": ("gtsam", "gtsam", "none"),
    "ours + all point cov.": ("ours", "colmap", "points"),
    "ours + snooping": ("ours", "colmap", "snooping"),
}


def run_size(n: int, ftol: float, timeout: float, only: list[int] | None) -> list[dict]:
    block, _ = simulate(n)
    print(
        f"\n== {block.n_images} images, {block.n_points} points, {block.n_observations} "
        f"observations (ftol {ftol:g}) =="
    )
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "block.pkl")
        with open(path, "wb") as fh:
            pickle.dump(block, fh)
        runs = {k: v for i, (k, v) in enumerate(RUNS.items()) if only is None or i in only}
        res = {}
        for name, (w, model, stats) in runs.items():
            r = spawn(path, w, ftol, model=model, stats=stats, timeout=timeout)
            res[name] = r
            if "error" in r:
                print(f"{name:24s} failed: {r['error']}")
                continue
            extra = (
                f"stats {fmt_t(r['stats_time'])}"
                if "stats_time" in r
                else f"setup {fmt_t(r.get('setup_time'))}"
            )
            print(
                f"{name:24s} solve {fmt_t(r['time']):>9s}  {extra:16s} iterations "
                f"{r['iterations']:3d}  cost {r['cost']:.10e}  behind {r['behind']}  peak "
                f"{r['maxrss_mb']:.0f} MB  (process CPU {r['process_cpu_s']:.1f} s)"
            )
            rows.append({"images": n, "name": name, "ftol": ftol, **r})

    def ratio(a, b, key):
        if a in res and b in res and "error" not in res[a] and "error" not in res[b]:
            return res[a][key] / res[b][key]
        return float("nan")

    base = res.get("ours (OPENCV set)", {})
    for peer, mine in (
        ("pycolmap OPENCV", "ours (OPENCV set)"),
        ("GTSAM Cal3DS2", "ours (Cal3DS2 set)"),
    ):
        if peer not in res or "error" in res[peer] or "error" in res.get(mine, {"error": 1}):
            continue
        a, b = res[mine], res[peer]
        rel = abs(a["cost"] - b["cost"]) / b["cost"]
        cal = "  ".join(
            f"{k} {(a['calibration'][k] - b['calibration'][k]) / a['calibration_std'][k]:+.1e}"
            for k in a["calibration_std"]
        )
        print(
            f"ours / {peer}: time {ratio(mine, peer, 'time'):.2f}, peak memory "
            f"{ratio(mine, peer, 'maxrss_mb'):.2f}; cost relative difference {rel:.1e} "
            f"({'agree' if rel <= 1e-6 else 'DIFFERENT'} at 1e-6)"
        )
        print(f"  calibration difference / our std: {cal}")
    if "error" not in base and base:
        for k in ("ours + all point cov.", "ours + snooping"):
            r = res.get(k)
            if r and "error" not in r:
                print(
                    f"{k}: statistics pass {fmt_t(r['stats_time'])} = "
                    f"{r['stats_time'] / r['time']:.2f} of the adjustment's time "
                    f"({fmt_t(base['stats_time'])} = {base['stats_time'] / base['time']:.2f} "
                    "with exterior and calibration covariances only)"
                )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[50, 250, 2000])
    ap.add_argument("--ftol", type=float, nargs="*", default=[1e-10])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument(
        "--runs",
        type=int,
        nargs="*",
        help="indices of the runs to make (default all): "
        + ", ".join(f"{i} {k}" for i, k in enumerate(RUNS)),
    )
    ap.add_argument("--timeout", type=float, default=3600.0, help="s per solver run")
    ap.add_argument("--json", help="write all rows to this file")
    ap.add_argument("--worker", choices=sorted(WORKERS), help=argparse.SUPPRESS)
    ap.add_argument("--block", help=argparse.SUPPRESS)
    ap.add_argument("--model", default="colmap", help=argparse.SUPPRESS)
    ap.add_argument("--stats", default="none", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        args.ftol = args.ftol[0]
        worker_main(args)
        return
    sizes = [21] if args.quick else args.sizes
    rows = []
    for ftol in args.ftol:
        for n in sizes:
            if n not in LAYOUTS:
                ap.error(f"--sizes: choose from {', '.join(map(str, LAYOUTS))}")
            rows += run_size(n, ftol, args.timeout, args.runs)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
