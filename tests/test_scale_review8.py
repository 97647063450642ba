"""Review 8 (scale): jobs on big inputs stay linear in time and bounded in memory.

No timing or memory assertions: each test pins the new path against an independent
computation and checks the structure that keeps memory bounded (blocks of a bounded size).
"""

from __future__ import annotations

import numpy as np
import pytest

pyproj = pytest.importorskip("pyproj")


def _utm_file(path, n: int, seed: int = 0) -> tuple[list[str], np.ndarray, list[str]]:
    """A point CSV in UTM 32N (EPSG:32632) of n points with a role column (some blank)."""
    rng = np.random.default_rng(seed)
    xyz = np.column_stack(
        [rng.uniform(4e5, 6e5, n), rng.uniform(5.0e6, 5.4e6, n), rng.uniform(0, 3000, n)]
    )
    ids = [f"p{i}" for i in range(n)]
    roles = np.array(["control", "check", ""])[rng.integers(0, 3, n)].tolist()
    body = "".join(
        f"{i},{x!r},{y!r},{z!r},{r}\n" for i, (x, y, z), r in zip(ids, xyz.tolist(), roles)
    )
    path.write_text("# crs: EPSG:32632\nid,x,y,z,role\n" + body)
    return ids, xyz, roles


def test_crs_convert_streams_blocks_and_matches_proj(cli, tmp_path, monkeypatch):
    """`crs convert` read the whole file and formatted the whole output in memory (1e7
    points: 3.2 GB peak); it converts block by block now, building the PROJ operation once,
    with the output of PROJ on all points at once."""
    import photogeom.crs as pcrs
    from photogeom.io import format_points_csv

    n = 60_000  # about 3 MB of text: several blocks of 1 MiB
    src = tmp_path / "utm.csv"
    ids, xyz, roles = _utm_file(src, n)
    sizes: list[int] = []
    built = {"n": 0}
    make = pcrs.points_converter

    def counting(*args, **kwargs):
        built["n"] += 1
        convert = make(*args, **kwargs)

        def run(points):
            sizes.append(len(points))
            return convert(points)

        return run

    monkeypatch.setattr(pcrs, "points_converter", counting)
    out = tmp_path / "geo.csv"
    code, _, err = cli("crs", "convert", src, "--to", "EPSG:4979", "-o", out)
    assert code == 0, err
    assert f"wrote {n} point(s)" in err
    assert built["n"] == 1
    assert sum(sizes) == n and len(sizes) >= 3 and max(sizes) < n // 2

    t = pyproj.Transformer.from_crs(32632, 4979, always_xy=True)
    expected = np.column_stack(t.transform(*xyz.T))
    text = format_points_csv(
        ids,
        expected,
        ["lon", "lat", "h"],
        extra={"role": [r or "control" for r in roles]},
        comments=["EPSG:32632 -> EPSG:4979", "crs: EPSG:4979"],
    )
    assert out.read_text() == text


def test_crs_convert_to_a_local_frame_in_blocks(cli, tmp_path):
    """Through a local frame (geocentric WGS 84 in between), block by block: the same as
    points_between on all points at once, also to standard output."""
    import photogeom.crs as pcrs

    n = 40_000
    src = tmp_path / "utm.csv"
    _, xyz, _ = _utm_file(src, n, seed=3)
    code, out, err = cli("crs", "convert", src, "--to", "enu:47.1,8.5,500")
    assert code == 0, err
    rows = [ln for ln in out.splitlines() if not ln.startswith("#")][1:]
    got = np.array([[float(v) for v in r.split(",")[1:4]] for r in rows])
    expected = pcrs.points_between(xyz, "EPSG:32632", "enu:47.1,8.5,500")
    assert got.shape == (n, 3)
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize(
    "src, dst",
    [
        ("EPSG:32632", "EPSG:4979"),
        ("EPSG:32632", "EPSG:32632"),
        ("enu:47.1,8.5,500", "EPSG:4978"),
        ("enu:47.1,8.5,500", "enu:47.2,8.4,400"),
        ("EPSG:4978", "enu:47.1,8.5,500"),
        ("EPSG:32632", "enu:47.1,8.5,500"),
    ],
)
def test_points_converter_equals_points_between_steps(src, dst):
    """The converter gives what the steps of points_between give (frame to geocentric WGS 84,
    PROJ, geocentric to frame), call after call."""
    import photogeom.crs as pcrs

    rng = np.random.default_rng(1)
    local = rng.uniform(-500, 500, (200, 3))
    pts = local if src.startswith("enu") else pcrs.points_between(local, "enu:47.1,8.5,500", src)
    convert = pcrs.points_converter(src, dst)
    f_src, f_dst = pcrs.frame_from_text(src), pcrs.frame_from_text(dst)
    step = f_src.to_ecef(pts) if f_src else pts
    mid_src = "EPSG:4978" if f_src else src
    mid_dst = "EPSG:4978" if f_dst else dst
    if mid_src != mid_dst:
        t = pyproj.Transformer.from_crs(mid_src, mid_dst, always_xy=True)
        step = np.column_stack(t.transform(*step.T))
    expected = f_dst.from_ecef(step) if f_dst else step
    for part in (pts[:70], pts[70:]):
        k = len(part)
        np.testing.assert_array_equal(convert(part), expected[:k] if k == 70 else expected[70:])
    assert convert(np.zeros((0, 3))).shape == (0, 3)
