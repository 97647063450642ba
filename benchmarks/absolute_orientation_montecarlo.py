"""Monte-Carlo study of the absolute orientation methods (the specification's protocol).

Run:  python benchmarks/absolute_orientation_montecarlo.py           (a few minutes)
      python benchmarks/absolute_orientation_montecarlo.py --quick   (fewer trials)

Random problems with uniformly distributed rotations (any angle), points in a 100 m cube,
scale 0.5-2, seeded. Tables:

A. accuracy of every method against least squares (the converged Gauss-Markov solution;
   checked on a sample of trials to equal the batched SVD, which then stands in for it),
   n from 3 to 10^6, three noise levels;
B. wrong correspondences (outlier fractions): least squares, closed form and RANSAC against
   the truth;
C. near-coplanar and near-collinear point sets: error against the truth, degenerate flags,
   the closed form with and without its plane-normal augmentation;
D. Gauss-Markov (and Gauss-Helmert) from naive initial values (s = 1, R = I, t = 0): success
   rate by rotation angle, and how the failures end;
E. reported (a-priori) standard deviations against the empirical spread of 1000 trials.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial.transform import Rotation

import photogeom as pg
from photogeom.errors import PhotogeomError

BATCH_METHODS = ("closed-form", "quaternion", "dual-quaternion", "gauss-helmert")
NAMES = ("tx", "ty", "tz", "scale", "omega", "phi", "kappa")


def make(B, n, sigma, seed, thick=1.0, collinear=False, sigma_source=0.0):
    """B problems: source (B, n, 3) and noisy target, true scale/rotation/shift."""
    rng = np.random.default_rng(seed)
    R = Rotation.random(B, random_state=seed).as_matrix()
    s = rng.uniform(0.5, 2.0, B)
    t = rng.normal(scale=1000.0, size=(B, 3))
    x = rng.uniform(-50, 50, (B, n, 3))
    if collinear:
        x[:, :, 1:] *= thick
    else:
        x[:, :, 2] *= thick
    X = s[:, None, None] * np.matmul(x, np.swapaxes(R, 1, 2)) + t[:, None, :]
    X = X + rng.normal(scale=sigma, size=X.shape)
    if sigma_source:
        x = x + rng.normal(scale=sigma_source, size=x.shape)
    return x, X, s, R, t


def rot_err_deg(Ra, Rb):
    """Rotation angle (deg) between stacks (B, 3, 3): ``2 asin(|Q - I|_F / sqrt(8))`` of
    ``Q = Ra.T Rb`` (accurate for tiny angles; raw matrices are orthogonalised first);
    NaN where either is NaN."""
    ok = np.isfinite(Ra).all(axis=(1, 2)) & np.isfinite(Rb).all(axis=(1, 2))
    out = np.full(Ra.shape[0], np.nan)
    if not ok.any():
        return out
    M = np.matmul(np.swapaxes(Ra[ok], 1, 2), Rb[ok])
    U, _, Vt = np.linalg.svd(M)
    Q = np.matmul(U, Vt)
    f = np.linalg.norm(Q - np.eye(3), axis=(1, 2))
    out[ok] = np.degrees(2 * np.arcsin(np.clip(f / np.sqrt(8.0), 0, 1)))
    return out


def q(a, p):
    a = np.asarray(a, dtype=float)
    a = a[np.isfinite(a)]
    return np.percentile(a, p) if a.size else np.nan


def section_a(quick):
    print("\nA. accuracy against least squares (LS = converged Gauss-Markov = batched SVD)")
    print("   rotation: angle of R_method.T R_LS [deg]; shift: |t - t_LS| [m]; "
          "median and 95th percentile over the trials; noise sigma on the target, 100 m cube")
    sizes = [(3, 400), (4, 400), (10, 400), (100, 200), (1000, 50), (100_000, 4), (1_000_000, 2)]
    if quick:
        sizes = [(3, 100), (10, 100), (1000, 10)]
    sig = (0.01, 0.1, 1.0)
    print(f"{'n':>8}{'sigma':>7}  {'method':<18}{'rot med':>10}{'rot 95%':>10}"
          f"{'shift med':>11}{'shift 95%':>11}{'|ds|/s med':>12}")
    checked = 0
    for n, B in sizes:
        for sigma in sig:
            if n >= 100_000 and sigma != 0.1:
                continue
            x, X, *_ = make(B, n, sigma, seed=n + int(sigma * 1000))
            ls = pg.absolute_orientation_batch(x, X, "svd")
            for i in range(min(3, B) if n <= 1000 else 0):  # GM is converged and equals SVD
                gm = pg.absolute_orientation(x[i], X[i], "gauss-markov")
                assert np.abs(gm.rotation - ls.rotation[i]).max() < 1e-9
                checked += 1
            for m in BATCH_METHODS:
                r = pg.absolute_orientation_batch(x, X, m)
                ang = rot_err_deg(ls.rotation, r.rotation)
                dt = np.linalg.norm(r.translation - ls.translation, axis=1)
                ds = np.abs(r.scale / ls.scale - 1)
                print(f"{n:>8}{sigma:>7}  {m:<18}{q(ang, 50):>10.2e}{q(ang, 95):>10.2e}"
                      f"{q(dt, 50):>11.2e}{q(dt, 95):>11.2e}{q(ds, 50):>12.2e}")
    print(f"   (Gauss-Markov run on {checked} of the trials: equal to the SVD to 1e-9)")


def section_b(quick):
    print("\nB. wrong correspondences (n = 100, sigma = 0.01 m): rotation error against the "
          "truth [deg]")
    T = 20 if quick else 60
    print(f"{'outliers':>9}  {'method':<20}{'median':>10}{'95%':>10}{'success':>9}"
          f"{'inlier mask exact':>19}")
    for frac in (0.0, 0.05, 0.2, 0.5):
        x, X, s, R, t = make(T, 100, 0.01, seed=int(frac * 100) + 7)
        rng = np.random.default_rng(3)
        truth_in = np.ones((T, 100), dtype=bool)
        for b in range(T):
            k = int(frac * 100)
            bad = rng.choice(100, k, replace=False)
            X[b, bad] = X[b, rng.permutation(bad)]
            d = np.linalg.norm(X[b] - (s[b] * x[b] @ R[b].T + t[b]), axis=1)
            truth_in[b] = d <= 0.05  # within the RANSAC threshold of the true transformation
        res = {}
        for m in ("svd", "closed-form"):
            r = pg.absolute_orientation_batch(x, X, m)
            res[m] = (rot_err_deg(R, r.rotation), None)
        errs, exact = [], []
        for b in range(T):
            try:
                f = pg.ransac_absolute_orientation(x[b], X[b], threshold=0.05, rng=b)
                errs.append(rot_err_deg(R[b][None], f.rotation[None])[0])
                exact.append(np.array_equal(f.inliers, truth_in[b]))
            except PhotogeomError:
                errs.append(np.nan)
                exact.append(False)
        res["RANSAC + svd"] = (np.array(errs), np.mean(exact))
        for m, (e, ex) in res.items():
            succ = np.mean(np.nan_to_num(e, nan=180) < 0.01)
            exs = "" if ex is None else f"{ex:.0%}"
            print(f"{frac:>9.0%}  {m:<20}{q(e, 50):>10.2e}{q(e, 95):>10.2e}{succ:>9.0%}{exs:>19}")


def section_c(quick):
    print("\nC. near-coplanar and near-collinear sets (n = 10, sigma = 0.01 m, 100 m extent): "
          "rotation error against the truth [deg], median")
    T = 100 if quick else 400
    head = f"{'shape':<10}{'thick':>7}{'flagged':>9}"
    cols = ("svd", "closed-form", "closed-form*", "quaternion", "dual-quaternion",
            "gauss-helmert")
    print(head + "".join(f"{c:>16}" for c in cols) + f"{'GM std/emp':>20}")
    print("   closed-form*: without the plane-normal augmentation (threshold 0); "
          "flagged: share of problems reported as degenerate; GM std/emp: reported / empirical "
          "standard deviation of the least determined angle (one geometry, 400 noise draws)")
    for shape in ("coplanar", "collinear"):
        for thick in (1.0, 0.1, 0.01, 0.001, 0.0):
            x, X, s, R, t = make(T, 10, 0.01, seed=11, thick=thick, collinear=shape == "collinear")
            line = f"{shape:<10}{thick:>7}"
            errs = []
            flagged = None
            for c in cols:
                if c == "closed-form*":
                    from photogeom.orientation.absolute_direct import solve_closed_form

                    sol = solve_closed_form(x, X, coplanar_threshold=0.0)
                    rot = np.where((sol.degenerate | sol.reflection)[:, None, None], np.nan,
                                   sol.rotation)
                else:
                    r = pg.absolute_orientation_batch(x, X, c)
                    rot = r.rotation
                    if c == "svd":
                        flagged = 1 - r.valid.mean()
                errs.append(q(rot_err_deg(R, rot), 50))
            ratio = ""
            if thick > 0 or shape == "coplanar":
                ok = pg.absolute_orientation_batch(x, X, "svd").valid
                # a problem away from gimbal lock (|phi| < 60 deg), where angles are linear
                phi = np.abs(pg.angles_from_rotation(R, "transposed")[1])
                ok &= phi < np.radians(60)
                if ok.sum() > 10:
                    i0 = int(np.flatnonzero(ok)[0])
                    try:
                        gm = pg.absolute_orientation(x[i0], X[i0], "gauss-markov",
                                                     sigma_target=0.01)
                        # same geometry, new noise: empirical spread of kappa about the truth
                        xs = np.broadcast_to(x[i0], (T, *x.shape[1:]))
                        Xt = s[i0] * x[i0] @ R[i0].T + t[i0]
                        Xs = Xt + np.random.default_rng(5).normal(scale=0.01, size=(T, 10, 3))
                        rb = pg.absolute_orientation_batch(xs, Xs, "svd")
                        # the least determined angle (largest reported std dev)
                        names = ("omega", "phi", "kappa")
                        j = int(np.argmax([gm.std_errors_prior[a] for a in names]))
                        a_true = pg.angles_from_rotation(R[i0], "transposed")[j]
                        da = (rb.angles("transposed")[j] - a_true + np.pi) % (2 * np.pi) - np.pi
                        ratio = f"{gm.std_errors_prior[names[j]] / np.nanstd(da):.2f} ({names[j]})"
                    except PhotogeomError as exc:
                        ratio = type(exc).__name__
            print(line + f"{flagged:>9.0%}" + "".join(f"{e:>16.2e}" for e in errs)
                  + f"{ratio:>20}")


def section_d(quick):
    print("\nD. Gauss-Markov from naive initial values (s = 1, R = I, t = 0), n = 10, "
          "sigma = 0.01 m")
    T = 40 if quick else 150
    print(f"{'rotation [deg]':>15}{'success':>9}{'s < 0':>8}{'saddle':>8}{'no conv.':>9}"
          f"{'iter. med':>10}    Gauss-Helmert: success")
    rng = np.random.default_rng(21)
    for lo, hi in ((0, 45), (45, 90), (90, 135), (135, 180)):
        counts = {"ok": 0, "neg": 0, "saddle": 0, "conv": 0}
        its = []
        gh_ok = 0
        gh_T = max(T // 5, 5)
        for k in range(T):
            ang = np.radians(rng.uniform(lo, hi))
            axis = rng.normal(size=3)
            R = Rotation.from_rotvec(axis / np.linalg.norm(axis) * ang).as_matrix()
            x = rng.uniform(-50, 50, (10, 3))
            X = 1.3 * x @ R.T + rng.normal(scale=300, size=3) + rng.normal(scale=0.01,
                                                                           size=(10, 3))
            ref = pg.absolute_orientation(x, X, "svd", statistics=False)
            try:
                f = pg.absolute_orientation(x, X, "gauss-markov", initial="zeros", max_iter=100)
                if np.abs(f.rotation - ref.rotation).max() < 1e-8:
                    counts["ok"] += 1
                    its.append(f.iterations)
                else:
                    counts["saddle"] += 1
            except pg.ConvergenceError as exc:
                msg = str(exc)
                if "<= 0" in msg:
                    counts["neg"] += 1
                elif "stationary point" in msg:
                    counts["saddle"] += 1
                else:
                    counts["conv"] += 1
            if k < gh_T:
                try:
                    g = pg.absolute_orientation(x, X, "gauss-helmert", iterate=True,
                                                initial="zeros", max_iter=100)
                    d = pg.absolute_orientation(x, X, "gauss-helmert")
                    gh_ok += np.abs(g.rotation - d.rotation).max() < 1e-8
                except PhotogeomError:
                    pass
        med = np.median(its) if its else np.nan
        print(f"{f'{lo}-{hi}':>15}{counts['ok'] / T:>9.0%}{counts['neg'] / T:>8.0%}"
              f"{counts['saddle'] / T:>8.0%}{counts['conv'] / T:>9.0%}{med:>10.0f}"
              f"    {gh_ok / gh_T:.0%} of {gh_T}")
    print("   s < 0: converged to the point-reflected fit (reported as ConvergenceError); "
          "saddle: a stationary point that is not the minimum (detected, reported)")


def section_e(quick):
    print("\nE. reported (a-priori) standard deviations / empirical spread of the trials")
    T = 300 if quick else 1000
    configs = [
        ("GM n=4 sigma=0.01", dict(n=4, sigma=0.01)),
        ("GM n=10 sigma=0.01", dict(n=10, sigma=0.01)),
        ("GM n=100 sigma=0.1", dict(n=100, sigma=0.1)),
        ("GM n=10 near-coplanar 0.05", dict(n=10, sigma=0.01, thick=0.05)),
        ("GH n=10 sx=0.005 sX=0.02", dict(n=10, sigma=0.02, sigma_source=0.005)),
    ]
    print(f"{'configuration':<28}" + "".join(f"{k:>8}" for k in NAMES))
    for label, c in configs:
        rng_seed = 77
        x1, X1, s, R, t = make(1, c["n"], 0.0, seed=rng_seed, thick=c.get("thick", 1.0))
        rng = np.random.default_rng(1)
        xs = np.broadcast_to(x1[0], (T, c["n"], 3)).copy()
        Xs = X1[0] + rng.normal(scale=c["sigma"], size=(T, c["n"], 3))
        ss = c.get("sigma_source", 0.0)
        if ss:
            xs = xs + rng.normal(scale=ss, size=xs.shape)
            r = pg.absolute_orientation_batch(xs, Xs, "gauss-helmert", sigma_source=ss,
                                              sigma_target=c["sigma"])
            fit = pg.absolute_orientation(xs[0], Xs[0], "gauss-helmert", sigma_source=ss,
                                          sigma_target=c["sigma"])
        else:
            r = pg.absolute_orientation_batch(xs, Xs, "svd")
            fit = pg.absolute_orientation(xs[0], Xs[0], "gauss-markov", sigma_target=c["sigma"])
        w, p, k = r.angles("transposed")
        est = np.column_stack([r.translation, r.scale, w, p, k])
        truth = np.r_[t[0], s[0], pg.angles_from_rotation(R[0], "transposed")]
        d = est - truth
        d[:, 4:] = (d[:, 4:] + np.pi) % (2 * np.pi) - np.pi
        emp = np.nanstd(d, axis=0, ddof=1)
        rep = np.array([fit.std_errors_prior[n] for n in NAMES])
        print(f"{label:<28}" + "".join(f"{v:>8.3f}" for v in rep / emp))
    print(f"   ({T} trials each; 1.000 = perfect; the sampling error of the ratio is about "
          f"{1 / np.sqrt(2 * T):.1%})")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    section_a(args.quick)
    section_b(args.quick)
    section_c(args.quick)
    section_d(args.quick)
    section_e(args.quick)
    print(f"\n(total {time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
