"""The command line on big point files against the Python API on arrays, and start-up times.

Usage::

    python benchmarks/cli.py [--n 1000000] [--repeat 3]

For each job the script times the ``photogeom`` command on a CSV of ``n`` points (a fresh
process: start-up, reading, computing, writing) against two references measured in the same
run, interleaved:

* the same computation through the Python API on arrays already in memory;
* the floor of any command on that file: a fresh Python process in which pyarrow reads the
  input CSV (``pyarrow.csv.read_csv``, all threads) and writes it back
  (``pyarrow.csv.write_csv``, which formats the floats), with no computation and no checks.

The fixed cost of the command (start-up, imports, the fsync of the output) is shown by the
same command on the first 1000 points of the file. The peak memory of the command and of the
floor is printed against the size of the input file. Start-up: ``photogeom --help``,
``import photogeom`` and an 8-point ``transform estimate`` (wall and CPU time, medians).

Numbers depend on the machine and its load; compare the ratios.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import photogeom as pg
from photogeom.io import read_points, write_points

PY = sys.executable
#: Children keep their bytecode (as an installed package does) in a cache of their own, also
#: where PYTHONDONTWRITEBYTECODE is set: start-up is measured without compiling sources.
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
ENV["PYTHONPYCACHEPREFIX"] = os.path.join(tempfile.gettempdir(), "photogeom-bench-pycache")


def run(cmd: list[str]) -> tuple[float, float, float]:
    """Wall time (s), CPU time (s) and peak memory (MiB) of a command.

    The command runs under a small launcher process (``python -c``) that starts it: a child
    forked directly from this process would count this process's memory (the test arrays)
    in its peak until it execs.
    """
    launcher = (
        "import os, subprocess, sys, time\n"
        "t0 = time.perf_counter()\n"
        "p = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL)\n"
        "_, st, ru = os.wait4(p.pid, 0)\n"
        "print(time.perf_counter() - t0, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0,"
        " os.waitstatus_to_exitcode(st))\n"
    )
    out = subprocess.run([PY, "-c", launcher, *cmd], capture_output=True, text=True, env=ENV)
    wall, cpu, peak, code = out.stdout.split()
    if int(code) != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed: {out.stderr}")
    return float(wall), float(cpu), float(peak)


#: The floor: pyarrow reads the input file and writes it back, nothing else.
FLOOR = "import sys, pyarrow.csv as c\nc.write_csv(c.read_csv(sys.argv[1]), sys.argv[2])\n"


def best_of(f, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=float, default=1e6, help="points per file")
    ap.add_argument("--repeat", type=int, default=3, help="repetitions (minimum taken)")
    args = ap.parse_args()
    n = int(args.n)
    cli = [PY, "-m", "photogeom"]
    rpc_path = str(pg.datasets.path("ikonos"))
    rpc = pg.RPC.from_file(rpc_path)
    c0, c1, r0, r1 = rpc.image_bounds
    rng = np.random.default_rng(1)
    pix = np.column_stack([rng.uniform(c0, c1, n), rng.uniform(r0, r1, n), rng.uniform(0, 100, n)])
    ids = [f"p{i}" for i in range(n)]
    helmert = pg.Similarity3D.from_helmert(
        -87.0, -98.0, -121.0, 0.1, -0.247, 0.3, 1.5, convention="position_vector"
    )

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        pix_csv, ground_csv, out_csv = d / "pix.csv", d / "ground.csv", d / "out.csv"
        xyz_csv, params = d / "xyz.csv", d / "helmert.json"
        write_points(pix_csv, ids, pix, ["col", "row", "h"])
        lon, lat = rpc.localize(pix[:, 0], pix[:, 1], pix[:, 2])
        write_points(ground_csv, ids, np.column_stack([lon, lat, pix[:, 2]]), ["lon", "lat", "h"])
        xyz = rng.uniform(-1e6, 1e6, (n, 3)) + np.array([4e6, 3e5, 5e6])
        write_points(xyz_csv, ids, xyz, ["x", "y", "z"])
        params.write_text(__import__("json").dumps({"model_parameters": helmert.to_dict()}))

        jobs = [
            (
                "rpc localize",
                [*cli, "rpc", "localize", rpc_path, str(pix_csv), "-o", str(out_csv)],
                lambda: rpc.localize(pix[:, 0], pix[:, 1], pix[:, 2], full_output=True),
                pix_csv,
            ),
            (
                "rpc project",
                [*cli, "rpc", "project", rpc_path, str(ground_csv), "-o", str(out_csv)],
                lambda: rpc.project(lon, lat, pix[:, 2]),
                ground_csv,
            ),
            (
                "transform apply",
                [*cli, "transform", "apply", str(params), str(xyz_csv), "-o", str(out_csv)],
                lambda: helmert.apply(xyz),
                xyz_csv,
            ),
        ]
        print(f"n = {n:,} points; command (fresh process) vs the API on arrays and vs the "
              f"floor (pyarrow read + write, fresh process); minimum of {args.repeat}, "
              "interleaved")  # fmt: skip
        print("'1e3 pts': the same command on the first 1000 points (start-up, imports, fsync)")
        print(f"{'job':<16} {'command':>8} {'1e3 pts':>7} {'API':>7} {'floor':>7} {'/API':>6} "
              f"{'/floor':>6} {'peak MiB':>8} {'floor MiB':>9} {'file MiB':>8} "
              f"{'mem/file':>8}")  # fmt: skip
        floor_out = d / "floor.csv"
        print(f"load average at start: {', '.join(f'{v:.1f}' for v in os.getloadavg())}")
        for name, cmd, api, src in jobs:
            small = d / f"small-{src.name}"
            with open(src) as fh:
                small.write_text("".join(line for _, line in zip(range(1001), fh)))
            small_cmd = [str(small) if c == str(src) else c for c in cmd]
            cli_runs, small_runs, api_times, floor_runs = [], [], [], []
            for _ in range(args.repeat):  # interleaved: the machine's drift hits all alike
                cli_runs.append(run(cmd))
                small_runs.append(run(small_cmd))
                api_times.append(best_of(api, 1))
                floor_runs.append(run([PY, "-c", FLOOR, str(src), str(floor_out)]))
            wall = min(r[0] for r in cli_runs)
            peak = max(r[2] for r in cli_runs)
            t_small = min(r[0] for r in small_runs)
            t_api = min(api_times)
            t_floor = min(r[0] for r in floor_runs)
            floor_peak = max(r[2] for r in floor_runs)
            size = src.stat().st_size / 2**20
            print(f"{name:<16} {wall:7.2f}s {t_small:6.2f}s {t_api:6.3f}s {t_floor:6.2f}s "
                  f"{wall / t_api:6.1f} {wall / t_floor:6.2f} {peak:8.0f} {floor_peak:9.0f} "
                  f"{size:8.0f} {peak / size:8.2f}")  # fmt: skip

        # reading and writing alone: the block reader against Python's csv module
        import csv

        def csv_module():
            with open(pix_csv, newline="") as fh:
                rows = list(csv.reader(fh))[1:]
            np.array([[float(r[1]), float(r[2]), float(r[3])] for r in rows])

        t_read = best_of(lambda: read_points(pix_csv), args.repeat)
        t_csv = best_of(csv_module, args.repeat)
        t_write = best_of(lambda: write_points(out_csv, ids, pix, ["col", "row", "h"]), 1)
        print(f"read_points {t_read:.2f}s (Python csv module + float(): {t_csv:.2f}s, "
              f"ratio {t_read / t_csv:.2f}); write_points {t_write:.2f}s")  # fmt: skip

        # start-up
        small = str(pg.datasets.path("lecture_fiducials"))
        starts = [
            ("photogeom --help", [*cli, "--help"]),
            ("import photogeom", [PY, "-c", "import photogeom"]),
            ("python -c pass", [PY, "-c", "pass"]),
            ("8-point estimate", [*cli, "transform", "estimate", "similarity2d", small]),
        ]
        print("start-up (median of 7 runs): wall / CPU")
        for name, cmd in starts:
            run(cmd)  # warm-up: bytecode written, files in the page cache
            runs = [run(cmd) for _ in range(7)]
            w = statistics.median(r[0] for r in runs)
            c = statistics.median(r[1] for r in runs)
            print(f"  {name:<18} {w:6.3f}s / {c:6.3f}s")
        print(f"load average: {', '.join(f'{v:.1f}' for v in os.getloadavg())} "
              f"on {os.cpu_count()} cores")  # fmt: skip


if __name__ == "__main__":
    main()
