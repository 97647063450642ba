"""Long mutation-fuzzing run of every reader, by hand (not part of the test suite).

    PYTHONPATH=src python tests/fuzz/run_mutations.py [-n 5000] [--seed 1] [--limit 2.0]
        [--target rpc-text ...] [--save findings/]

For each reader: ``n`` inputs, each 1-4 random mutations of a seed file (bundled data).
Prints per reader the inputs run, the findings (exceptions other than photogeom's own), the
inputs slower than ``--limit`` seconds, the slowest input and the total time. Findings and
slow inputs are written to ``--save`` (one file each) to be turned into regression tests.
Exit code 1 when there is any finding or slow input.
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from harness import TARGETS, mutate, run_one


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=5000, help="inputs per reader")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--limit", type=float, default=2.0, help="seconds; slower inputs are findings")
    ap.add_argument("--target", action="append", choices=sorted(TARGETS))
    ap.add_argument("--save", type=Path, default=None, help="directory for failing inputs")
    args = ap.parse_args(argv)
    names = args.target or list(TARGETS)
    bad_total = 0
    print(f"{'reader':16s} {'inputs':>7s} {'refused':>8s} {'findings':>9s} {'>limit':>7s} "
          f"{'slowest s':>10s} {'total s':>8s}")  # fmt: skip
    for name in names:
        target = TARGETS[name]
        seeds = target.seeds()
        rng = random.Random(f"{args.seed}-{name}")
        findings: dict[str, tuple[bytes, str]] = {}
        slow = 0
        refused = 0
        slowest = 0.0
        t_start = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            for k in range(args.n):
                data = mutate(rng.choice(seeds), rng)
                out = run_one(target, data, Path(tmp))
                slowest = max(slowest, out.seconds)
                if out.error is not None and out.ok:
                    refused += 1
                if out.seconds > args.limit:
                    slow += 1
                    _save(args.save, name, f"slow-{k}", data)
                if not out.ok:
                    tb = "".join(traceback.format_exception(out.error)[-3:])
                    key = f"{type(out.error).__name__}: {tb.strip().splitlines()[-3]}"
                    if key not in findings:
                        findings[key] = (data, tb)
                        _save(args.save, name, f"finding-{k}", data)
        n_find = len(findings)
        bad_total += n_find + slow
        print(f"{name:16s} {args.n:7d} {refused:8d} {n_find:9d} {slow:7d} {slowest:10.3f} "
              f"{time.perf_counter() - t_start:8.1f}", flush=True)  # fmt: skip
        for key, (_, tb) in findings.items():
            print(f"    finding {key}\n{tb}", flush=True)
    return 1 if bad_total else 0


def _save(directory: Path | None, name: str, tag: str, data: bytes) -> None:
    if directory is None:
        return
    directory.mkdir(parents=True, exist_ok=True)
    (directory / f"{name}-{tag}.bin").write_bytes(data)


if __name__ == "__main__":
    sys.exit(main())
