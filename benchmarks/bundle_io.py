"""Interchange benchmark: reading and writing BAL, Bundler and COLMAP blocks, with peers.

Run:  python benchmarks/bundle_io.py            (250 images, ~1 M observations)
      python benchmarks/bundle_io.py --quick    (smaller, for a smoke run)

Prints, from one run on this machine (wall time of one call each, best of ``--repeat``):
photogeom's ``read_bal`` / ``write_bal`` against GTSAM's ``SfmData.FromBalFile`` /
``writeBAL`` on the same file, and ``read_colmap`` / ``write_colmap`` against pycolmap's
``Reconstruction(dir)`` / ``write_text`` (``write_binary`` for the binary model) on the same
model; ratios peer / photogeom (> 1: photogeom is faster); ``read_bundler`` /
``write_bundler`` (no peer reads Bundler files here). Also the time per observation at two
sizes, to show the readers are
linear in their input, and the CSV block folder read as written and with every cell quoted
(a spreadsheet export), which reads at the same rate.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from photogeom.bundle import (
    Block,
    projected_pixels,
    read_bal,
    read_bundler,
    read_colmap,
    read_csv_block,
    write_bal,
    write_bundler,
    write_colmap,
    write_csv_block,
)
from photogeom.camera.metashape import MetashapeCalibration


def synthetic(m: int, p: int, per_point: int, seed: int = 0) -> Block:
    """A BAL-type block: m images on a grid above p points, each point seen in per_point."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(m)))
    cx, cy = np.meshgrid(np.arange(side) * 20.0, np.arange(side) * 20.0)
    cx, cy = cx.ravel()[:m], cy.ravel()[:m]
    ext = np.column_stack(
        [cx, cy, np.full(m, 100.0), rng.normal(0, 0.02, (m, 2)), rng.uniform(-3, 3, m)]
    )
    cams = {i: MetashapeCalibration(4000, 3000, 3000.0, k1=-0.05, k2=0.01) for i in range(m)}
    obs_i = rng.integers(0, m, size=(p, per_point))
    # points near their first image, seen from per_point images (distinct where possible)
    xyz = np.column_stack([cx[obs_i[:, 0]], cy[obs_i[:, 0]], np.zeros(p)])
    xyz += rng.normal(0, 5, (p, 3))
    oi = obs_i.ravel()
    op = np.repeat(np.arange(p), per_point)
    key = np.unique(oi * p + op, return_index=True)[1]
    key.sort()
    oi, op = oi[key], op[key]
    b = Block.from_arrays(
        cameras=cams,
        image_ids=range(m),
        image_camera=range(m),
        exterior=ext,
        point_ids=range(p),
        xyz=xyz,
        obs_image_ids=oi,
        obs_point_ids=op,
        uv=np.zeros((oi.size, 2)),
        sigma=1.0,
        free=("f", "k1", "k2"),
    )
    uv, _ = projected_pixels(b)
    return b.with_observations(uv=uv + rng.normal(0, 0.5, uv.shape))


def best(fn, repeat: int) -> float:
    out = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return min(out)


def run(m: int, p: int, per_point: int, repeat: int) -> None:
    b = synthetic(m, p, per_point)
    n = b.n_observations
    print(f"\nblock: {m} images, {p} points, {n} observations")
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        bal = d / "problem.txt"
        t_wb = best(lambda: write_bal(b, bal), repeat)
        t_rb = best(lambda: read_bal(bal), repeat)
        print(
            f"  BAL    write {t_wb:7.3f} s  read {t_rb:7.3f} s  "
            f"({1e6 * t_rb / n:.2f} us per observation read)"
        )
        try:
            import gtsam

            t_g = best(lambda: gtsam.SfmData.FromBalFile(str(bal)), repeat)
            data = gtsam.SfmData.FromBalFile(str(bal))
            t_gw = best(lambda: gtsam.writeBAL(str(d / "g.txt"), data), repeat)
            print(
                f"  GTSAM  write {t_gw:7.3f} s  read {t_g:7.3f} s  ratio GTSAM / photogeom: "
                f"write {t_gw / t_wb:.2f}, read {t_g / t_rb:.2f}"
            )
        except ImportError:
            print("  GTSAM not installed")
        out = d / "bundle.out"
        t_wo = best(lambda: write_bundler(b, out), repeat)
        t_ro = best(lambda: read_bundler(out, image_size=(4000, 3000)), repeat)
        print(
            f"  Bundler write {t_wo:6.3f} s  read {t_ro:7.3f} s  "
            f"({1e6 * t_ro / n:.2f} us per observation read)"
        )
        t_text = colmap_rows(b, d / "colmap", repeat, binary=False)
        colmap_rows(b, d / "colmap-bin", repeat, binary=True, text_read=t_text)
        csv_dir = d / "csv"
        t_wv = best(lambda: write_csv_block(b, csv_dir), repeat)
        t_rv = best(lambda: read_csv_block(csv_dir), repeat)
        quoted = d / "csv-quoted"
        quoted.mkdir()
        for f in csv_dir.glob("*.csv"):
            lines = f.read_text().splitlines()
            cells = [
                ln if ln.startswith("#") else ",".join(f'"{c}"' if c else "" for c in ln.split(","))
                for ln in lines
            ]
            (quoted / f.name).write_text("\n".join(cells) + "\n")
        t_rq = best(lambda: read_csv_block(quoted), repeat)
        print(
            f"  CSV    write {t_wv:7.3f} s  read {t_rv:7.3f} s  "
            f"({1e6 * t_rv / n:.2f} us per observation read; every cell quoted: {t_rq:.3f} s)"
        )


def colmap_rows(b: Block, col: Path, repeat: int, *, binary: bool, text_read=None) -> float:
    """Print the rows of the COLMAP text or binary model (photogeom, pycolmap); the read
    time of photogeom."""
    n = b.n_observations
    kind = "binary" if binary else "text"
    t_w = best(lambda: write_colmap(b, col, binary=binary), repeat)
    t_r = best(lambda: read_colmap(col, image_key="id"), repeat)
    vs = f"; text / binary read {text_read / t_r:.1f}" if text_read else ""
    print(
        f"  COLMAP {kind} write {t_w:7.3f} s  read {t_r:7.3f} s  "
        f"({1e6 * t_r / n:.2f} us per observation read{vs})"
    )
    try:
        import pycolmap

        t_p = best(lambda: pycolmap.Reconstruction(str(col)), repeat)
        rec = pycolmap.Reconstruction(str(col))
        out = col.parent / f"pycolmap-{kind}"
        out.mkdir()
        write = rec.write_binary if binary else rec.write_text
        t_pw = best(lambda: write(str(out)), repeat)
        print(
            f"  pycolmap {kind} write {t_pw:5.3f} s  read {t_p:7.3f} s  ratio pycolmap / "
            f"photogeom: write {t_pw / t_w:.2f}, read {t_p / t_r:.2f}"
        )
    except ImportError:
        print("  pycolmap not installed")
    return t_r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    sizes = [(50, 20000, 5), (250, 100000, 10)] if not a.quick else [(20, 2000, 4), (50, 8000, 4)]
    for m, p, k in sizes:
        run(m, p, k, a.repeat)


if __name__ == "__main__":
    main()
