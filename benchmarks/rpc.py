"""RPC projection and localisation of 1e6 points: photogeom vs rpcm, ratios from one run.

Peer: rpcm 1.4.10 (Centre Borelli). rpcm declares srtm4 (a compiled SRTM reader that does not
build everywhere) as a dependency but needs it only for DEM heights; install rpcm without
dependencies plus the modules it imports:

    pip install --no-deps rpcm==1.4.10
    pip install rasterio geojson pyproj      # (in photogeom's "test" extra)

This script registers a stand-in ``srtm4`` module when the real one is missing.

For each bundled RPC file, 1e6 random image points over the whole image at heights in the
model's range are localised, and the resulting ground points projected, by both libraries
(same points, same process; best of ``--repeat`` runs). rpcm's localisation is its iterative
inversion (for the Pleiades file its vendor image-to-ground polynomials are removed so that
both libraries solve the same problem). For SkySat the heights are restricted to
``HEIGHT_OFF .. HEIGHT_OFF + HEIGHT_SCALE / 2`` because rpcm's iteration does not converge at
low heights on that model. Agreement of the results is printed too.

Run: ``python benchmarks/rpc.py [--points 1000000] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import sys
import time
import types

import numpy as np

import photogeom as pg
from photogeom.rpc import RPC

NAMES = ("quickbird", "ikonos", "skysat", "pleiades", "worldview2")


def _rpcm():
    if "srtm4" not in sys.modules:
        try:
            import srtm4  # noqa: F401
        except ImportError:
            sys.modules["srtm4"] = types.ModuleType("srtm4")
    try:
        import rpcm
    except ImportError:
        sys.exit("rpcm is not installed: pip install --no-deps rpcm==1.4.10 (see the docstring)")
    return rpcm


def _rpcm_model(rpcm, rpc: RPC, name: str):
    if name == "quickbird":  # rpcm reads only numbered keys; give it GDAL-style metadata
        model = rpcm.RPCModel(rpc.to_gdal_metadata())
    else:
        model = rpcm.rpc_from_rpc_file(str(pg.datasets.path(name)))
    for attr in ("lon_num", "lon_den", "lat_num", "lat_den"):
        if hasattr(model, attr):
            delattr(model, attr)
    return model


def _best(repeat: int, fn, *args) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn(*args)
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rpcm = _rpcm()
    n = args.points
    print(f"{n} points per file; best of {args.repeat}; times in seconds")
    head = (
        f"{'file':<11} {'project':>9} {'rpcm':>8} {'ratio':>6}   {'localize':>9} {'rpcm':>8} "
        f"{'ratio':>6}   {'max |d px|':>10} {'max |d deg|':>11}"
    )
    print(head)
    print("-" * len(head))
    ratios_p, ratios_l = [], []
    for name in NAMES:
        rpc = RPC.from_file(pg.datasets.path(name))
        ref = _rpcm_model(rpcm, rpc, name)
        rng = np.random.default_rng(0)
        c0, c1, r0, r1 = rpc.image_bounds
        col = rng.uniform(c0, c1, n)
        row = rng.uniform(r0, r1, n)
        lo, hi = rpc.height_range
        if name == "skysat":
            lo, hi = rpc.height_off, rpc.height_off + 0.5 * rpc.height_scale
        h = rng.uniform(lo, hi, n)
        rpc.localize(col[:10], row[:10], h[:10])  # build the cached approximate inverse
        rep = args.repeat
        t_loc, (lon, lat) = _best(rep, rpc.localize, col, row, h)
        with np.errstate(all="ignore"):
            t_loc_ref, (lon2, lat2) = _best(rep, ref.localization, col, row, h)
        t_prj, (c, r) = _best(rep, rpc.project, lon, lat, h)
        t_prj_ref, (c2, r2) = _best(rep, ref.projection, lon, lat, h)
        d_px = max(np.max(np.abs(c - c2)), np.max(np.abs(r - r2)))
        d_deg = max(np.max(np.abs(lon - lon2)), np.max(np.abs(lat - lat2)))
        ratios_p.append(t_prj_ref / t_prj)
        ratios_l.append(t_loc_ref / t_loc)
        print(
            f"{name:<11} {t_prj:9.3f} {t_prj_ref:8.3f} {ratios_p[-1]:6.1f}   {t_loc:9.3f} "
            f"{t_loc_ref:8.3f} {ratios_l[-1]:6.1f}   {d_px:10.1e} {d_deg:11.1e}"
        )
    print(
        f"speed-up vs rpcm (geometric mean): projection {np.exp(np.mean(np.log(ratios_p))):.1f}x, "
        f"localisation {np.exp(np.mean(np.log(ratios_l))):.1f}x; smallest: projection "
        f"{min(ratios_p):.1f}x, localisation {min(ratios_l):.1f}x"
    )


if __name__ == "__main__":
    main()
