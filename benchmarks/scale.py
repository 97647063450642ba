"""Point clouds larger than memory: throughput, peak memory and Dask scaling.

Generates a LAZ cloud (point format 6, one extra dimension, a CRS record) of ``--points``
points chunk by chunk, then transforms it with a 3D similarity by

* a plain laspy + numpy loop (read a chunk, transform, set x/y/z, write), the peer;
* ``photogeom.io.transform_cloud`` in this process;
* ``transform_cloud(scheduler=...)`` on a Dask local cluster of N = 1 and 2 workers, one
  single-threaded LAZ codec each (cluster start-up included in the time, and printed);

each in its own process, whose peak resident memory is reported (for the Dask runs: the
client's, and the largest worker's). Then it checks the output against the
in-memory result on a subset, and the absolute orientation of ``--orientation-points``
pairs as a ``dask.array`` against the in-memory ``absolute_orientation``.

    python benchmarks/scale.py                       # 2e7 points (a few minutes)
    python benchmarks/scale.py --points 2e8          # the 2e8-point run (~2 GB of LAZ)
    python benchmarks/scale.py --dask-orientation 1e9  # also 1e9 lazily generated pairs

Throughput ratios are against the laspy loop measured in the same run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SRC = Path(__file__).resolve().parents[1] / "src"
if str(SRC) not in sys.path:
    sys.path.insert(0, str(SRC))

import photogeom as pg  # noqa: E402

T = pg.Similarity3D.from_angles(1.00002, 0.01, -0.02, 0.9, [512000.0, 5400000.0, 410.0])


def generate(path: Path, n: int, chunk: int = 1_000_000) -> None:
    """A LAZ cloud of n points (1 km x 1 km x 50 m, mm resolution), written chunk by chunk."""
    import laspy

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.add_extra_dim(laspy.ExtraBytesParams(name="amplitude", type=np.float32))
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.zeros(3)
    header.add_crs(pg.crs.parse_crs("EPSG:32632"))
    rng = np.random.default_rng(0)
    with laspy.open(path, mode="w", header=header, do_compress=True) as w:
        for i in range(0, n, chunk):
            m = min(chunk, n - i)
            rec = laspy.ScaleAwarePointRecord.zeros(m, header=header)
            rec.x = rng.uniform(0, 1000, m)
            rec.y = rng.uniform(0, 1000, m)
            rec.z = rng.uniform(0, 50, m)
            rec.intensity = rng.integers(0, 65535, m, dtype=np.uint16)
            rec.gps_time = np.arange(i, i + m) * 1e-5
            rec["amplitude"] = rng.normal(size=m).astype(np.float32)
            w.write_points(rec)


def laspy_loop(src: str, dst: str, chunk: int) -> None:
    """The peer: what one writes with laspy and numpy alone."""
    import laspy

    with laspy.open(src) as r:
        header = r.header.copy()
        corners = np.array(
            [
                [x, y, z]
                for x in (header.mins[0], header.maxs[0])
                for y in (header.mins[1], header.maxs[1])
                for z in (header.mins[2], header.maxs[2])
            ]
        )
        c = T.apply(corners)
        header.offsets = np.round(0.5 * (c.min(axis=0) + c.max(axis=0)))
        with laspy.open(dst, mode="w", header=header) as w:
            for pts in r.chunk_iterator(chunk):
                xyz = np.c_[pts.x, pts.y, pts.z] @ (T.scale * T.rotation.T) + T.translation
                raw = np.rint((xyz - header.offsets) / header.scales).astype(np.int32)
                pts.X, pts.Y, pts.Z = raw[:, 0], raw[:, 1], raw[:, 2]
                pts.offsets = header.offsets
                w.write_points(pts)


def run_one(kind: str, src: str, dst: str, chunk: int) -> None:
    t0 = time.perf_counter()
    startup = 0.0
    if kind == "laspy":
        laspy_loop(src, dst, chunk)
    elif kind == "photogeom":
        pg.io.transform_cloud(src, dst, T, chunk_size=chunk)
    else:  # local:N, the cluster started first so that its start-up is reported apart
        with pg.distributed.scheduler_client(kind) as client:
            startup = time.perf_counter() - t0
            pg.io.transform_cloud(src, dst, T, chunk_size=chunk, scheduler=client)
            seconds = time.perf_counter() - t0
            workers = client.run(_peak_mb)
        print(
            json.dumps(
                {"seconds": seconds, "startup": startup, "worker_peak_mb": max(workers.values())}
            )
        )
        return
    print(json.dumps({"seconds": time.perf_counter() - t0, "startup": startup}))


def _peak_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def measure(kind: str, src: Path, dst: Path, chunk: int) -> dict:
    """Run one job in a child process; wall time and the child's peak RSS (largest single
    process among it and its waited-for descendants, from wait4)."""
    env = dict(os.environ, PYTHONPATH=str(SRC))
    proc = subprocess.Popen(
        [sys.executable, __file__, "--run-one", kind, str(src), str(dst), str(chunk)],
        stdout=subprocess.PIPE,
        env=env,
        text=True,
    )
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    if status != 0:
        raise SystemExit(f"{kind} failed (status {status})")
    res = json.loads(out.strip().splitlines()[-1])
    res["peak_mb"] = usage.ru_maxrss / 1024.0
    # CPU time of the job and of the processes it waited for (Dask workers): less sensitive
    # than wall time to what else runs on a shared machine
    res["cpu"] = usage.ru_utime + usage.ru_stime
    return res


def _burn(_: int) -> float:
    t = time.perf_counter()
    x = 0
    for i in range(5_000_000):
        x += i
    return time.perf_counter() - t


def available_speedup() -> float:
    """What two processes gain over one on this machine right now: the same pure-Python loop
    twice in one process, then in two (a shared machine may give no second core)."""
    from concurrent.futures import ProcessPoolExecutor

    t0 = time.perf_counter()
    _burn(0), _burn(1)
    one = time.perf_counter() - t0
    with ProcessPoolExecutor(2) as ex:
        list(ex.map(_burn, [0]))  # start the processes before timing
        t0 = time.perf_counter()
        list(ex.map(_burn, [0, 1]))
        two = time.perf_counter() - t0
    return one / two


def check_subset(src: Path, dst: Path, m: int = 200_000) -> tuple[bool, bool]:
    """Output equals the in-memory result on the first and the last m points; header/CRS."""
    import laspy

    n = pg.io.cloud_info(src).point_count
    info = pg.io.cloud_info(dst)
    ok = info.point_count == n and info.crs_name == pg.io.cloud_info(src).crs_name
    for a in (0, max(0, n - m)):
        x = pg.io.read_cloud_xyz(src, a, a + m)
        expect = np.rint((T.apply(x) - info.offsets) / info.scales)
        with laspy.open(dst) as r:
            r.seek(a)
            p = r.read_points(min(m, n - a))
        ok &= bool(np.array_equal(np.c_[p.X, p.Y, p.Z], expect))
    return ok, info.extra_dimensions == ("amplitude",)


def orientation(n: int, scheduler: str) -> None:
    import dask.array as da

    rng = np.random.default_rng(1)
    x = rng.uniform(0, 1000, (n, 3))
    X = T.apply(x) + rng.normal(scale=0.01, size=(n, 3))
    t0 = time.perf_counter()
    ref = pg.absolute_orientation(x, X, method="svd", statistics=False)
    t_mem = time.perf_counter() - t0
    dx = da.from_array(x, chunks=(1_000_000, 3), name=False)  # name=False: no hashing
    dX = da.from_array(X, chunks=(1_000_000, 3), name=False)
    t0 = time.perf_counter()
    fit = pg.distributed.absolute_orientation(dx, dX, scheduler=scheduler)
    t_da = time.perf_counter() - t0
    print(
        f"absolute orientation, n = {n:.0e}: in memory {t_mem:.2f} s, dask.array "
        f"({scheduler}) {t_da:.2f} s; |ds| = {abs(fit.scale - ref.scale):.1e}, "
        f"max |dR| = {np.abs(fit.rotation - ref.rotation).max():.1e}, "
        f"max |dt| = {np.abs(fit.translation - ref.translation).max():.1e} m"
    )


def lazy_orientation(n: int, scheduler: str) -> None:
    import dask.array as da

    chunk = 5_000_000
    x = da.random.default_rng(2).uniform(0, 1000, size=(n, 3), chunks=(chunk, 3))
    X = x.map_blocks(T.apply, dtype=float)
    t0 = time.perf_counter()
    fit = pg.distributed.absolute_orientation(x, X, scheduler=scheduler)
    dt = time.perf_counter() - t0
    print(
        f"absolute orientation of {n:.0e} lazily generated pairs ({scheduler}): {dt:.1f} s, "
        f"{n / dt:.3g} pairs/s; |scale - true| = {abs(fit.scale - T.scale):.1e}, "
        f"max |R - true| = {np.abs(fit.rotation - T.rotation).max():.1e}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=float, default=2e7)
    ap.add_argument("--chunk-size", type=int, default=1_000_000)
    ap.add_argument("--dir", type=Path, default=None, help="Work directory (default: temp).")
    ap.add_argument("--workers", default="1,2", help="Dask local cluster sizes.")
    ap.add_argument("--orientation-points", type=float, default=1e7)
    ap.add_argument(
        "--dask-orientation",
        type=float,
        default=0,
        help="Also orient this many lazily generated pairs (e.g. 1e9).",
    )
    ap.add_argument("--run-one", nargs=4, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.run_one:
        kind, src, dst, chunk = args.run_one
        run_one(kind, src, dst, int(chunk))
        return
    if args.dir is not None:
        args.dir.mkdir(parents=True, exist_ok=True)
        benchmark(args, args.dir)
        return
    with tempfile.TemporaryDirectory(prefix="photogeom-scale-") as work:  # removed after
        benchmark(args, Path(work))


def benchmark(args: argparse.Namespace, work: Path) -> None:
    """The benchmark of ``main`` with its files in ``work``."""
    n = int(args.points)
    src = work / f"cloud-{n}.laz"
    if not src.exists() or pg.io.cloud_info(src).point_count != n:
        t0 = time.perf_counter()
        generate(src, n)
        print(
            f"generated {n:.3g} points in {time.perf_counter() - t0:.1f} s "
            f"({src.stat().st_size / 1e6:.0f} MB LAZ)"
        )
    print(
        f"cores: {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}; chunk "
        f"{args.chunk_size} points; 2 processes vs 1 (pure Python): {available_speedup():.2f}x"
    )
    rows = []
    kinds = ["laspy", "photogeom"] + [f"local:{w}" for w in args.workers.split(",") if w]
    for kind in kinds:
        dst = work / f"out-{kind.replace(':', '')}.laz"
        r = measure(kind, src, dst, args.chunk_size)
        ok, extra = check_subset(src, dst)
        r.update(kind=kind, ok=ok, extra=extra)
        rows.append(r)
        dst.unlink()
        print(
            f"  {kind}: {r['seconds']:.1f} s (cluster start-up {r['startup']:.1f} s), "
            f"peak {r['peak_mb']:.0f} MB"
            + (f", largest worker {r['worker_peak_mb']:.0f} MB" if "worker_peak_mb" in r else ""),
            flush=True,
        )
    base = rows[0]["seconds"]
    print(
        f"{'job':<26}{'time [s]':>10}{'points/s':>12}{'vs laspy':>10}{'CPU [s]':>10}"
        f"{'CPU vs laspy':>14}{'peak MB':>10}  check"
    )
    for r in rows:
        r["peak_mb"] = max(r["peak_mb"], r.get("worker_peak_mb", 0.0))
    names = {"laspy": "laspy + numpy loop", "photogeom": "transform_cloud"}
    for r in rows:
        name = names.get(r["kind"], f"dask {r['kind']} workers")
        print(
            f"{name:<26}{r['seconds']:>10.1f}{n / r['seconds']:>12.3g}"
            f"{base / r['seconds']:>10.2f}{r['cpu']:>10.1f}{rows[0]['cpu'] / r['cpu']:>14.2f}"
            f"{r['peak_mb']:>10.0f}  "
            f"{'equal' if r['ok'] else 'DIFFERENT'}{'' if r['extra'] else ' (extra dim lost)'}"
        )
    by = {r["kind"]: r["seconds"] for r in rows}
    if "local:1" in by and "local:2" in by:
        st = {r["kind"]: r["seconds"] - r["startup"] for r in rows}
        print(
            f"dask scaling 1 -> 2 workers: {by['local:1'] / by['local:2']:.2f}x "
            f"({st['local:1'] / st['local:2']:.2f}x without the cluster start-up); "
            f"a pure-Python loop in 2 processes vs 1, measured now: {available_speedup():.2f}x"
        )
    if args.orientation_points:
        orientation(int(args.orientation_points), "threads")
    if args.dask_orientation:
        lazy_orientation(int(args.dask_orientation), "local")


if __name__ == "__main__":
    main()
