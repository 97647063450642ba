"""CRS of results: ``--crs`` options of the commands, the CRS carried in fits, reports and
point files, geographic coordinates refused, GNSS positions from WGS 84 into a block's local
frame and back (checked against PROJ's own topocentric conversion)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import photogeom as pg
from photogeom.errors import InputError

pyproj = pytest.importorskip("pyproj")


def _topocentric(lat0, lon0, h0, inverse=False):
    """PROJ's geographic 3D (degrees) <-> ENU pipeline, independent of photogeom."""
    steps = (
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
        "+step +proj=cart +ellps=WGS84 "
        f"+step +proj=topocentric +ellps=WGS84 +lat_0={lat0!r} +lon_0={lon0!r} +h_0={h0!r}"
    )
    t = pyproj.Transformer.from_pipeline(steps)
    if not inverse:
        return lambda p: np.column_stack(t.transform(p[:, 0], p[:, 1], p[:, 2]))
    return lambda p: np.column_stack(
        t.transform(p[:, 0], p[:, 1], p[:, 2], direction=pyproj.enums.TransformDirection.INVERSE)
    )


# --- the library: which CRSs a Cartesian computation accepts -------------------------------------


@pytest.mark.parametrize(
    "crs, kind, unit",
    [
        ("EPSG:25832", "projected", "m"),
        ("EPSG:25832+5783", "projected", "m"),
        ("EPSG:2263", "projected", "ftUS"),
        ("EPSG:4978", "geocentric", "m"),
        ("enu:47.1,8.5,500", "local ENU", "m"),
        (32632, "projected", "m"),
    ],
)
def test_cartesian_crs_accepts_and_describes(crs, kind, unit):
    info = pg.crs.cartesian_crs(crs, what="--crs")
    assert info.kind == kind and info.unit == unit and not info.angular
    assert info.text == (f"EPSG:{crs}" if isinstance(crs, int) else crs)
    if kind != "local ENU":
        assert pyproj.CRS(info.text) == pyproj.CRS(crs)


@pytest.mark.parametrize("crs", ["EPSG:4326", "EPSG:4979", "EPSG:4326+5773", "EPSG:4258"])
def test_geographic_crs_is_refused_with_the_fix(crs):
    with pytest.raises(InputError) as exc:
        pg.crs.cartesian_crs(crs, what="--target-crs")
    msg = str(exc.value)
    assert msg.startswith("--target-crs") and "geographic" in msg and "degrees" in msg
    assert "photogeom crs convert" in msg and "--to enu" in msg


def test_other_refusals_name_the_option():
    with pytest.raises(InputError, match="--crs: 'EPSG:99999' is not a coordinate reference"):
        pg.crs.cartesian_crs("EPSG:99999", what="--crs")
    with pytest.raises(InputError, match="vertical CRS"):
        pg.crs.cartesian_crs("EPSG:5783", what="--crs")
    with pytest.raises(InputError, match="3D Cartesian system"):
        pg.crs.cartesian_crs("EPSG:4978", what="--crs", dim=2)
    with pytest.raises(InputError, match="coordinates in m, but the unit given is 'mm'"):
        pg.crs.cartesian_crs("EPSG:25832", what="--crs", unit="mm")
    assert pg.crs.cartesian_crs("EPSG:25832", unit="metre").unit == "m"
    with pytest.raises(InputError, match="enu:lat0,lon0,h0"):
        pg.crs.frame_from_text("enu:47,8")
    with pytest.raises(InputError, match="lat0"):
        pg.crs.frame_from_text("enu:95,8,0")


def test_local_frame_text_round_trip():
    f = pg.crs.LocalFrame(47.123456789012, -8.5, 512.25)
    assert pg.crs.frame_from_text(f.to_text()) == f
    assert pg.crs.frame_from_text("EPSG:4979") is None
    with pytest.raises(InputError, match="WGS 84"):
        pg.crs.LocalFrame(47, 8, 0, "GRS80").to_text()


def test_curvature_note_gives_the_drop_over_the_extent():
    info = pg.crs.cartesian_crs("EPSG:25832")
    pts = np.array([[500000.0, 5200000.0, 400.0], [502000.0, 5200000.0, 410.0]])
    note = pg.crs.curvature_note(info, pts)
    assert "1000 m from the centre" in note
    assert f"{pg.crs.curvature_drop(1000.0):.2g} m below" in note  # 0.078 m
    assert pg.crs.curvature_note(info, np.array([[0.0, 0, 0], [200.0, 0, 0]])) is None  # 0.8 mm
    assert pg.crs.curvature_note(pg.crs.cartesian_crs("EPSG:4978"), pts) is None
    ft = pg.crs.cartesian_crs("EPSG:2263")
    d_ft = 1000.0 / (1200.0 / 3937.0)
    note = pg.crs.curvature_note(ft, np.array([[0.0, 0.0, 0.0], [2 * d_ft, 0.0, 0.0]]))
    assert "1000 m from the centre" in note


@given(
    lat0=st.floats(-80, 80),
    lon0=st.floats(-179, 179),
    h0=st.floats(-100, 3000),
    e=st.floats(-5000, 5000),
    n=st.floats(-5000, 5000),
    u=st.floats(-500, 500),
)
def test_points_between_a_local_frame_and_wgs84_equal_proj(lat0, lon0, h0, e, n, u):
    frame = f"enu:{lat0!r},{lon0!r},{h0!r}"
    enu = np.array([[e, n, u], [0.0, 0.0, 0.0]])
    lonlath = pg.crs.points_between(enu, frame, "EPSG:4979")
    ref = _topocentric(lat0, lon0, h0, inverse=True)(enu)
    np.testing.assert_allclose(lonlath[:, :2], ref[:, :2], atol=1e-10, rtol=0)
    np.testing.assert_allclose(lonlath[:, 2], ref[:, 2], atol=1e-6, rtol=0)
    back = pg.crs.points_between(lonlath, "EPSG:4979", frame)
    np.testing.assert_allclose(back, enu, atol=1e-6, rtol=0)


# --- fits record their CRS -----------------------------------------------------------------------


@pytest.fixture
def pairs3d(tmp_path):
    rng = np.random.default_rng(7)
    x = rng.uniform([0, 0, 0], [1500, 1200, 60], (12, 3))
    T = pg.Similarity3D.from_angles(1.00002, 0.001, -0.002, 0.4, [480000.0, 5300000.0, 250.0])
    X = T.apply(x) + rng.normal(0, 0.01, x.shape)
    lines = ["id,x,y,z,X,Y,Z"] + [
        f"{i}," + ",".join(repr(float(v)) for v in (*a, *b)) for i, (a, b) in enumerate(zip(x, X))
    ]
    p = tmp_path / "pairs.csv"
    p.write_text("\n".join(lines) + "\n")
    return p, x, X


def test_fit_with_crs_records_and_refuses_degrees(pairs3d):
    _, x, X = pairs3d
    fit = pg.absolute_orientation(x, X)
    assert fit.crs is None and "crs" not in fit.to_dict()
    f2 = fit.with_crs("EPSG:32632", source_crs="enu:47,8,400")
    assert (f2.crs, f2.source_crs) == ("EPSG:32632", "enu:47,8,400")
    d = f2.to_dict()
    assert d["crs"] == "EPSG:32632" and d["source_crs"] == "enu:47,8,400"
    s = f2.summary()
    assert "target CRS: EPSG:32632 (WGS 84 / UTM zone 32N)" in s
    assert "source CRS: local ENU frame at lat 47, lon 8, h 400 m" in s
    assert f2.with_crs() is f2
    with pytest.raises(InputError, match="geographic"):
        fit.with_crs("EPSG:4326")


def test_transform_estimate_and_apply_carry_the_crs(cli, pairs3d, tmp_path):
    p, _, _ = pairs3d
    params, report = tmp_path / "h.json", tmp_path / "h.html"
    code, out, err = cli(
        "transform", "estimate", "similarity3d", p, "--target-crs", "EPSG:32632",
        "--source-crs", "enu:47.1,8.5,400", "--output-params", params, "--report", report,
        "--json",
    )  # fmt: skip
    assert code == 0, err
    d = json.loads(out)
    assert d["crs"] == "EPSG:32632" and d["source_crs"] == "enu:47.1,8.5,400"
    assert d["residual_unit"] == "m"  # from the CRS
    # points 1.9 km apart: the curvature note says how far map coordinates are from Cartesian
    assert any("not Cartesian" in n and "EPSG:32632" in n for n in d["notes"])
    saved = json.loads(params.read_text())
    assert saved["crs"] == "EPSG:32632"
    html = report.read_text()
    assert "WGS 84 / UTM zone 32N" in html and "local ENU frame at lat 47.1" in html
    code, out, err = cli("transform", "estimate", "similarity3d", p, "--target-crs", "EPSG:32632")
    assert code == 0 and "target CRS" in out and "UTM zone 32N" in out

    pts = tmp_path / "new.csv"
    pts.write_text("# crs: enu:47.1,8.5,400\nid,x,y,z\n1,10,20,3\n")
    code, out, err = cli("transform", "apply", params, pts)
    assert code == 0, err
    assert "# crs: EPSG:32632" in out.splitlines()
    code, out, err = cli("transform", "apply", params, pts, "--crs", "EPSG:32632")
    assert code == 0 and "# crs: EPSG:32632" in out.splitlines()
    # a --crs contradicting the parameters' target CRS would mislabel the output
    code, out, err = cli("transform", "apply", params, pts, "--crs", "EPSG:25832")
    assert code == 2 and out == "" and "--crs EPSG:25832" in err and "EPSG:32632" in err
    back = tmp_path / "back.csv"
    back.write_text("# crs: EPSG:32632\nid,X,Y,Z\n1,480010,5300020,253\n")
    code, out, err = cli("transform", "apply", params, back, "--inverse")
    assert code == 0, err
    assert "# crs: enu:47.1,8.5,400" in out.splitlines()
    code, out, err = cli("transform", "apply", params, back)
    assert code == 2 and "records the CRS EPSG:32632" in err and "enu:47.1,8.5,400" in err
    geo = tmp_path / "geo.csv"
    geo.write_text("# crs: EPSG:4979\nid,x,y,z\n1,8.5,47.1,400\n")
    code, out, err = cli("transform", "apply", params, geo)
    assert code == 2 and "geographic" in err and "'# crs:' line" in err


def test_transform_estimate_refuses_degrees_and_unknown_crs(cli, pairs3d):
    p, _, _ = pairs3d
    args = ("transform", "estimate", "similarity3d", p)
    code, _, err = cli(*args, "--target-crs", "EPSG:4979")
    assert code == 2 and err.startswith("error: --target-crs EPSG:4979") and "crs convert" in err
    code, _, err = cli(*args, "--source-crs", "EPSG:123456")
    assert code == 2 and "--source-crs: 'EPSG:123456' is not a coordinate reference" in err
    code, _, err = cli(*args, "--target-crs", "EPSG:25832", "--unit", "mm")
    assert code == 2 and "unit given is 'mm'" in err
    code, _, err = cli("transform", "estimate", "similarity2d", p, "--target-crs", "EPSG:4978",
                       "--source-cols", "x,y", "--target-cols", "X,Y")  # fmt: skip
    assert code == 2 and "3D Cartesian system" in err


def test_transform_estimate_unit_from_a_feet_crs(cli, pairs3d):
    p, _, _ = pairs3d
    code, out, err = cli("transform", "estimate", "similarity3d", p, "--target-crs", "EPSG:2263",
                         "--json")  # fmt: skip
    assert code == 0, err
    assert json.loads(out)["residual_unit"] == "ftUS"


def test_orient_absolute_records_the_crs(cli, pairs3d, tmp_path):
    p, _, _ = pairs3d
    report = tmp_path / "a.html"
    code, out, err = cli("orient", "absolute", p, "--target-crs", "EPSG:32632", "--json",
                         "--report", report)  # fmt: skip
    assert code == 0, err
    d = json.loads(out)
    assert d["crs"] == "EPSG:32632" and d["source_crs"] is None and d["residual_unit"] == "m"
    assert "UTM zone 32N" in report.read_text()
    code, out, err = cli("orient", "absolute", p, "--target-crs", "EPSG:32632", "--compare",
                         "--json")  # fmt: skip
    assert code == 0 and json.loads(out)["crs"] == "EPSG:32632"
    code, out, err = cli("orient", "absolute", p, "--target-crs", "EPSG:32632", "--compare")
    assert code == 0 and "target CRS: EPSG:32632 (WGS 84 / UTM zone 32N)" in out
    code, _, err = cli("orient", "absolute", p, "--source-crs", "EPSG:4326")
    assert code == 2 and "--source-crs" in err and "geographic" in err


def test_crs_convert_records_the_output_crs(cli, tmp_path):
    pts = tmp_path / "g.csv"
    pts.write_text("id,lon,lat,h\na,8.5,47.1,500\nb,8.51,47.105,530\n")
    code, out, err = cli("crs", "convert", pts, "--from", "EPSG:4979", "--to", "enu",
                         "--origin", "47.1,8.5,500", "--cols", "lon,lat,h")  # fmt: skip
    assert code == 0, err
    assert "# crs: enu:47.1,8.5,500.0" in out.splitlines()
    enu = tmp_path / "enu.csv"
    enu.write_text(out)
    code, out, err = cli("crs", "convert", enu, "--from", "enu:47.1,8.5,500", "--to",
                         "EPSG:4979")  # fmt: skip
    assert code == 0, err
    assert "# crs: EPSG:4979" in out.splitlines()
    rows = [r.split(",") for r in out.splitlines() if r and not r.startswith("#")][1:]
    np.testing.assert_allclose(
        [[float(v) for v in r[1:]] for r in rows], [[8.5, 47.1, 500], [8.51, 47.105, 530]],
        atol=1e-9,
    )  # fmt: skip


# --- bundle adjustment: GNSS in WGS 84, the block in a local frame -------------------------------

ORIGIN = (47.1, 8.5, 500.0)
FRAME = "enu:47.1,8.5,500.0"


@pytest.fixture(scope="module")
def sim():
    return pg.simulate.uav_block(
        "FC300S", seed=1, strips=2, images_per_strip=4, tie_points_per_image=40
    )


@pytest.fixture(scope="module")
def geo_block(sim):
    """The simulated block (local frame at ORIGIN) with its GNSS positions in WGS 84 (lon,
    lat, h by PROJ's topocentric conversion)."""
    lonlath = _topocentric(*ORIGIN, inverse=True)(sim.block.gnss)
    return sim.block.replace(gnss=lonlath, crs=FRAME)


def test_gnss_into_the_local_frame_equals_proj(sim, geo_block):
    b = pg.bundle.gnss_into_block_crs(geo_block, "EPSG:4979")
    assert b.crs == FRAME
    np.testing.assert_allclose(b.gnss, sim.block.gnss, atol=1e-6, rtol=0)
    np.testing.assert_array_equal(b.gnss_sigma, sim.block.gnss_sigma)
    # the adjustment of the converted block is that of the block in the frame
    ref = pg.bundle_adjust(sim.block)
    fit = pg.bundle_adjust(b)
    assert fit.crs == FRAME
    assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-6)
    np.testing.assert_allclose(fit.block.exterior, ref.block.exterior, atol=1e-6)
    # ... and back to WGS 84: PROJ's inverse topocentric conversion of the adjusted centres
    got = fit.positions_in("EPSG:4979")
    want = _topocentric(*ORIGIN, inverse=True)(fit.block.exterior[:, :3])
    np.testing.assert_allclose(got[:, :2], want[:, :2], atol=1e-10, rtol=0)
    np.testing.assert_allclose(got[:, 2], want[:, 2], atol=1e-6, rtol=0)
    pts = fit.points_in("EPSG:4978")
    X = pyproj.Transformer.from_crs(4979, 4978, always_xy=True).transform(
        *_topocentric(*ORIGIN, inverse=True)(fit.block.xyz).T
    )
    np.testing.assert_allclose(pts, np.column_stack(X), atol=1e-6, rtol=0)


def test_gnss_frame_at_the_block_centre_and_refusals(sim, geo_block):
    ties = geo_block.replace(crs=None, role=np.full(geo_block.n_points, "tie"))
    b = pg.bundle.gnss_into_block_crs(ties, "EPSG:4979")
    frame = pg.crs.frame_from_text(b.crs)
    lon, lat, h = geo_block.gnss.T
    assert frame == pg.crs.LocalFrame.at_centroid(lat, lon, h)
    np.testing.assert_allclose(b.gnss.mean(axis=0)[:2], 0.0, atol=1e-3)
    with pytest.raises(InputError, match="control/check points are in a system"):
        pg.bundle.gnss_into_block_crs(geo_block.replace(crs=None), "EPSG:4979")
    with pytest.raises(InputError, match="records the CRS"):
        pg.bundle.gnss_into_block_crs(geo_block, "EPSG:4979", crs="EPSG:25832")
    with pytest.raises(InputError, match="no GNSS positions"):
        pg.bundle.gnss_into_block_crs(
            geo_block.replace(gnss=np.full_like(geo_block.gnss, np.nan)), "EPSG:4979"
        )
    with pytest.raises(InputError, match="records no CRS"):
        pg.bundle.positions_in(sim.block, "EPSG:4979")


def test_bundle_adjust_cli_gnss_crs_and_crs(cli, geo_block, tmp_path):
    folder = tmp_path / "geo"
    pg.bundle.write_csv_block(geo_block, folder)
    assert f"# crs: {FRAME}" in (folder / "points.csv").read_text()
    out_block, report, result = tmp_path / "adj", tmp_path / "b.html", tmp_path / "b.json"
    code, out, err = cli("bundle", "adjust", folder, "--gnss-crs", "EPSG:4979", "--json",
                         "--output", out_block, "--report", report, "--result", result)  # fmt: skip
    assert code == 0, err
    d = json.loads(out)
    assert d["crs"] == FRAME and d["crs_name"].startswith("local ENU frame at lat 47.1")
    g = d["georeferencing"]
    assert g["gnss_crs"] == "EPSG:4979" and g["n_gnss"] == 8 and g["block_crs"] == FRAME
    centres = np.array([[r[k] for k in ("X0", "Y0", "Z0")] for r in d["images"]])
    want = _topocentric(*ORIGIN, inverse=True)(centres)
    got = np.array([r["position_gnss_crs"] for r in d["images"]])
    np.testing.assert_allclose(got[:, :2], want[:, :2], atol=1e-10, rtol=0)
    np.testing.assert_allclose(got[:, 2], want[:, 2], atol=1e-6, rtol=0)
    # the adjusted block is in the local frame, GNSS included, and says so
    adj = pg.bundle.read_csv_block(out_block)
    assert adj.crs == FRAME and np.all(np.abs(adj.gnss) < 1e3)
    html = report.read_text()
    assert "local ENU frame at lat 47.1" in html and "Projection centres in EPSG:4979" in html
    assert f"{got[0, 0]:.9f}" in html and f"{got[0, 1]:.9f}" in html
    assert json.loads(result.read_text())["georeferencing"]["gnss_crs"] == "EPSG:4979"
    code, out, err = cli("bundle", "adjust", folder, "--gnss-crs", "EPSG:4979")
    assert code == 0 and "object coordinates: local ENU frame" in out and "EPSG:4979" in out


def test_bundle_adjust_cli_refusals(cli, geo_block, tmp_path):
    folder = tmp_path / "geo"
    pg.bundle.write_csv_block(geo_block, folder)
    code, _, err = cli("bundle", "adjust", folder, "--crs", "EPSG:4979")
    assert code == 2 and "--crs EPSG:4979" in err and "geographic" in err
    assert "--gnss-crs" in err and "crs convert" in err
    code, _, err = cli("bundle", "adjust", folder, "--crs", "EPSG:25832")
    assert code == 2 and "records the CRS enu:47.1,8.5,500.0" in err
    code, _, err = cli("bundle", "adjust", folder, "--gnss-crs", "EPSG:0")
    assert code == 2 and "--gnss-crs" in err
    bare = tmp_path / "bare"
    pg.bundle.write_csv_block(geo_block.replace(crs=None), bare)
    code, _, err = cli("bundle", "adjust", bare, "--gnss-crs", "EPSG:4979")
    assert code == 2 and "--gnss-crs EPSG:4979" in err and "--crs" in err
    assert "crs=" not in err


def test_bundle_adjust_cli_crs_recorded(cli, sim, tmp_path):
    folder = tmp_path / "plain"
    pg.bundle.write_csv_block(sim.block, folder)
    code, out, err = cli("bundle", "adjust", folder, "--crs", "EPSG:25832", "--json",
                         "--output", tmp_path / "adj")  # fmt: skip
    assert code == 0, err
    assert json.loads(out)["crs"] == "EPSG:25832"
    assert "# crs: EPSG:25832" in (tmp_path / "adj" / "points.csv").read_text()


# --- clouds: the parameter file carries the CRS ---------------------------------------------------


def test_cloud_register_and_transform_carry_the_crs(cli, tmp_path):
    pytest.importorskip("laspy")
    rng = np.random.default_rng(3)
    x = rng.uniform([0, 0, 0], [400, 300, 30], (600, 3))
    T = pg.Similarity3D.from_angles(1.00004, 0.01, -0.02, 0.7, [480000.0, 5300000.0, 250.0])
    src, dst = tmp_path / "scan.las", tmp_path / "ref.las"
    pg.io.write_cloud(src, x, scales=(1e-4, 1e-4, 1e-4), crs="EPSG:5555")
    pg.io.write_cloud(dst, T.apply(x), scales=(1e-4, 1e-4, 1e-4), crs="EPSG:32633")
    params = tmp_path / "p.json"
    code, _, err = cli("cloud", "register", src, dst, "--scheduler", "sync",
                         "--output-params", params)  # fmt: skip
    assert code == 0, err
    saved = json.loads(params.read_text())
    assert saved["crs"] == "EPSG:32633" and saved["source_crs"] == "EPSG:5555"
    out_las = tmp_path / "out.las"
    code, _, err = cli("cloud", "transform", src, out_las, "--params", params, "-q")
    assert code == 0, err
    assert pg.io.cloud_info(out_las).crs_name.startswith("EPSG:32633")
    code, _, err = cli("cloud", "transform", dst, out_las, "--params", params, "-q")
    assert code == 2 and "records the CRS EPSG:32633" in err
    geo = tmp_path / "geo.las"
    pg.io.write_cloud(geo, np.c_[rng.uniform(8, 9, 600), rng.uniform(47, 48, 600), x[:, 2]],
                      scales=(1e-8, 1e-8, 1e-3), crs="EPSG:4979")  # fmt: skip
    code, _, err = cli("cloud", "register", geo, dst, "--scheduler", "sync")
    assert code == 2 and "geographic" in err and "--to-crs" in err


# --- start-up stays light ------------------------------------------------------------------------


def test_pyproj_is_imported_only_when_a_crs_option_is_used(pairs3d):
    p, _, _ = pairs3d
    probe = (
        "import sys\n"
        "from photogeom.cli.main import main\n"
        "try:\n"
        "    main(sys.argv[1:])\n"
        "except SystemExit as e:\n"
        "    assert not e.code, e.code\n"
        "print('pyproj' in sys.modules, file=sys.stderr)\n"
    )
    args = ["transform", "estimate", "similarity3d", str(p), "--json"]
    for extra, want in (([], "False"), (["--target-crs", "EPSG:32632"], "True")):
        proc = subprocess.run(
            [sys.executable, "-c", probe, *args, *extra], capture_output=True, text=True,
            timeout=120,
        )  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        assert proc.stderr.strip().splitlines()[-1] == want


# --- resection and intersection: the ground CRS travels with the camera files ---------------------


def test_resection_and_intersection_carry_the_ground_crs(cli, tmp_path):
    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    eos = [
        pg.ExteriorOrientation.from_degrees(481000, 5300800, 1600, 2, 3, 10),
        pg.ExteriorOrientation.from_degrees(481600, 5300820, 1620, -1, 2, 8),
    ]
    rng = np.random.default_rng(0)
    g = np.column_stack(
        [
            rng.uniform(481050, 481550, 10),
            rng.uniform(5300750, 5301100, 10),
            rng.uniform(100, 300, 10),
        ]
    )
    cams, images = [], []
    for k, eo in enumerate(eos):
        xy = pg.project(g, io, eo) + rng.normal(0, 0.003, (10, 2))
        ctl, img = tmp_path / f"control{k}.csv", tmp_path / f"image{k}.csv"
        ctl.write_text(
            "id,X,Y,Z,x,y\n"
            + "".join(
                f"P{i}," + ",".join(repr(float(v)) for v in (*g[i], *xy[i])) + "\n"
                for i in range(10)
            )
        )
        img.write_text(
            "id,x,y\n"
            + "".join(f"P{i},{float(xy[i, 0])!r},{float(xy[i, 1])!r}\n" for i in range(10))
        )
        cam = tmp_path / f"cam{k}.json"
        code, out, err = cli(
            "orient", "resection", ctl, "--f", "152.14", "--x0", "0.008", "--y0", "-0.12",
            "--crs", "EPSG:32632", "--output-params", cam,
        )  # fmt: skip
        assert code == 0, err
        assert "ground CRS" in out and "UTM zone 32N" in out
        assert json.loads(cam.read_text())["crs"] == "EPSG:32632"
        cams.append(cam)
        images.append(img)
    code, out, err = cli(
        "orient", "intersection", *images, "--camera", cams[0], "--camera", cams[1]
    )
    assert code == 0, err
    assert "# crs: EPSG:32632" in out.splitlines()
    code, _, err = cli("orient", "intersection", *images, "--camera", cams[0], "--camera",
                       cams[1], "--crs", "EPSG:25832")  # fmt: skip
    assert code == 2 and "record the CRS EPSG:32632" in err
    code, _, err = cli("orient", "resection", tmp_path / "control0.csv", "--f", "152.14",
                       "--crs", "EPSG:4326")  # fmt: skip
    assert code == 2 and "--crs EPSG:4326" in err and "geographic" in err


def test_rpc_localize_records_wgs84_and_converts_with_crs(cli, tmp_path):
    ikonos = pg.datasets.path("ikonos")
    px = tmp_path / "px.csv"
    px.write_text("id,col,row\na,100,200\nb,5000,6000\nfar,-50000,3\n")
    code, out, err = cli("rpc", "localize", ikonos, px, "--height", "30")
    assert code == 0, err
    assert "# crs: EPSG:4979" in out.splitlines()
    rows = [ln.split(",") for ln in out.splitlines() if not ln.startswith("#")][1:]
    lonlath = np.array([[float(v) for v in r[1:4]] for r in rows])
    code, out, err = cli("rpc", "localize", ikonos, px, "--height", "30", "--crs", "EPSG:32721")
    assert code == 0, err
    lines = out.splitlines()
    assert "# crs: EPSG:32721" in lines and "id,x,y,z,status" in lines
    rows = [ln.split(",") for ln in lines if not ln.startswith("#")][1:]
    xyz = np.array([[float(v) for v in r[1:4]] for r in rows])
    t = pyproj.Transformer.from_crs(4979, 32721, always_xy=True)
    want = np.column_stack(t.transform(*lonlath.T))
    np.testing.assert_allclose(xyz, want, atol=1e-6, rtol=0)
    code, out, err = cli("rpc", "localize", ikonos, px, "--height", "30", "--crs", "EPSG:32721",
                         "--json")  # fmt: skip
    d = json.loads(out)
    assert d["crs"] == "EPSG:32721" and d["points"][0]["x"] == pytest.approx(want[0, 0])
    code, _, err = cli("rpc", "localize", ikonos, px, "--height", "30", "--crs", "EPSG:0")
    assert code == 2 and "--crs" in err


def test_rpc_project_takes_points_in_any_crs(cli, tmp_path):
    ikonos = pg.datasets.path("ikonos")
    lonlath = np.array([[-56.24, -34.948, 30.0], [-56.166, -34.9165, 12.0]])
    geo = tmp_path / "geo.csv"
    geo.write_text("id,lon,lat,h\n" + "".join(f"p{i},{a!r},{b!r},{c!r}\n" for i, (a, b, c)
                                              in enumerate(lonlath.tolist())))  # fmt: skip
    code, out, err = cli("rpc", "project", ikonos, geo, "--json")
    assert code == 0, err
    want = [[p["col"], p["row"]] for p in json.loads(out)["points"]]
    t = pyproj.Transformer.from_crs(4979, 32721, always_xy=True)
    utm = np.column_stack(t.transform(*lonlath.T))
    rows = "".join(f"p{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in enumerate(utm.tolist()))
    plain, recorded = tmp_path / "utm.csv", tmp_path / "utm-crs.csv"
    plain.write_text("id,x,y,z\n" + rows)
    recorded.write_text("# crs: EPSG:32721\nid,x,y,z\n" + rows)
    for args in ((plain, "--crs", "EPSG:32721"), (recorded,)):
        code, out, err = cli("rpc", "project", ikonos, *args, "--json")
        assert code == 0, err
        got = [[p["col"], p["row"]] for p in json.loads(out)["points"]]
        np.testing.assert_allclose(got, want, atol=1e-6)
    code, _, err = cli("rpc", "project", ikonos, plain)
    assert code == 2 and "lon,lat,h" in err


def test_two_point_files_give_their_crs_lines(cli, pairs3d, tmp_path):
    _, x, X = pairs3d
    src, dst = tmp_path / "model.csv", tmp_path / "ground.csv"
    src.write_text("# crs: enu:47.1,8.5,400\nid,x,y,z\n" + "".join(
        f"{i},{a!r},{b!r},{c!r}\n" for i, (a, b, c) in enumerate(x.tolist())))  # fmt: skip
    dst.write_text("# crs: EPSG:32632\nid,X,Y,Z\n" + "".join(
        f"{i},{a!r},{b!r},{c!r}\n" for i, (a, b, c) in enumerate(X.tolist())))  # fmt: skip
    for cmd in (("transform", "estimate", "similarity3d"), ("orient", "absolute")):
        code, out, err = cli(*cmd, src, dst, "--json")
        assert code == 0, err
        d = json.loads(out)
        assert d["crs"] == "EPSG:32632" and d["source_crs"] == "enu:47.1,8.5,400"
        code, _, err = cli(*cmd, src, dst, "--target-crs", "EPSG:25832")
        assert code == 2 and "records the CRS EPSG:32632" in err and "--target-crs" in err
    geo = tmp_path / "geo.csv"
    geo.write_text("# crs: EPSG:4979\n" + dst.read_text().split("\n", 1)[1])
    code, _, err = cli("orient", "absolute", src, geo)
    assert code == 2 and "geo.csv ('# crs:' line) EPSG:4979" in err and "geographic" in err


def test_bundle_in_map_coordinates_gets_the_curvature_note(cli, tmp_path):
    # a block about 1 km across: 2 cm of curvature drop at its edge
    big = pg.simulate.uav_block(
        "FC300S", seed=2, strips=2, images_per_strip=4, tie_points_per_image=40, gsd=0.25
    )
    xy = pg.bundle_adjust(big.block).block.xyz[:, :2]
    half = np.sqrt(np.max(np.sum((xy - xy.mean(axis=0)) ** 2, axis=1)))
    assert pg.crs.curvature_drop(half) > 1e-3
    folder = tmp_path / "big"
    pg.bundle.write_csv_block(big.block, folder)
    code, out, err = cli("bundle", "adjust", folder, "--crs", "EPSG:25832", "--json")
    assert code == 0, err
    notes = [n for n in json.loads(out)["notes"] if "not Cartesian" in n]
    assert len(notes) == 1
    d = float(notes[0].split(" m from the centre")[0].rsplit(" ", 1)[1])
    assert d == pytest.approx(half, rel=1e-3)  # of the adjusted points
    code, out, err = cli("bundle", "adjust", folder, "--crs", "EPSG:4978", "--json")
    assert code == 0 and not any("not Cartesian" in n for n in json.loads(out)["notes"])


def test_dlt_estimate_records_the_ground_crs(cli, tmp_path):
    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    eo = pg.ExteriorOrientation.from_degrees(481000, 5300800, 1600, 2, 3, 10)
    rng = np.random.default_rng(1)
    g = rng.uniform([480600, 5300500, 100], [481400, 5301100, 300], (12, 3))
    xy = pg.project(g, io, eo) + rng.normal(0, 0.003, (12, 2))
    p = tmp_path / "gcp.csv"
    p.write_text(
        "# crs: EPSG:32632\nid,X,Y,Z,x,y\n"
        + "".join(f"P{i}," + ",".join(repr(float(v)) for v in (*g[i], *xy[i])) + "\n"
                  for i in range(12))
    )  # fmt: skip
    code, out, err = cli("camera", "dlt", "estimate", p, "--json")
    assert code == 0, err
    assert json.loads(out)["crs"] == "EPSG:32632"
    code, out, err = cli("camera", "dlt", "estimate", p)
    assert code == 0 and "ground CRS" in out and "UTM zone 32N" in out
    code, _, err = cli("camera", "dlt", "estimate", p, "--crs", "EPSG:25832")
    assert code == 2 and "records the CRS EPSG:32632" in err
