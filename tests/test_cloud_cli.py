"""`photogeom cloud info | transform | register` and `photogeom crs convert`."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg

laspy = pytest.importorskip("laspy")
pyproj = pytest.importorskip("pyproj")


@pytest.fixture
def clouds(tmp_path):
    rng = np.random.default_rng(3)
    x = rng.uniform([0, 0, 0], [400, 300, 30], (4000, 3))
    T = pg.Similarity3D.from_angles(1.00004, 0.01, -0.02, 0.7, [480000.0, 5300000.0, 250.0])
    X = T.apply(x)
    src, dst = tmp_path / "scan.laz", tmp_path / "ref.laz"
    pg.io.write_cloud(src, x, scales=(1e-4, 1e-4, 1e-4))
    pg.io.write_cloud(dst, X, scales=(1e-4, 1e-4, 1e-4), crs="EPSG:32633")
    return src, dst, T


def test_info_text_and_json(cli, clouds):
    _, dst, _ = clouds
    code, out, err = cli("cloud", "info", str(dst))
    assert code == 0, err
    assert "4000 points" in out and "EPSG:32633" in out and "point format 6" in out
    code, out, err = cli("cloud", "info", str(dst), "--json")
    d = json.loads(out)
    assert d["point_count"] == 4000 and d["compressed"] is True


def test_register_then_transform(cli, clouds, tmp_path):
    src, dst, T = clouds
    params = tmp_path / "p.json"
    code, out, err = cli(
        "cloud",
        "register",
        str(src),
        str(dst),
        "--check-every",
        "10",
        "--chunk-size",
        "1500",
        "--json",
        "--output-params",
        str(params),
        "--scheduler",
        "sync",
    )
    assert code == 0, err
    d = json.loads(out)
    assert d["n_check"] == 400 and d["n_control"] == 3600
    assert d["target_crs"].startswith("EPSG:32633")
    assert d["scale"] == pytest.approx(T.scale, abs=1e-8)
    # quantisation of both files to 0.1 mm: check residuals of that size
    assert d["check_rmse"] < 2e-4
    out_laz = tmp_path / "out.laz"
    code, out, err = cli(
        "cloud",
        "transform",
        str(src),
        str(out_laz),
        "--params",
        str(params),
        "--crs",
        "EPSG:32633",
        "--chunk-size",
        "999",
        "-q",
        "--scheduler",
        "threads",
    )
    assert code == 0, err
    got = pg.io.read_cloud_xyz(out_laz)
    np.testing.assert_allclose(got, pg.io.read_cloud_xyz(dst), atol=3e-4)
    assert pg.io.cloud_info(out_laz).crs_name.startswith("EPSG:32633")
    code, out, err = cli("cloud", "register", str(src), str(dst), "--scheduler", "sync")
    assert code == 0 and "scale 1.0000400" in out and " deg " in out  # --angle-unit default


def test_transform_between_crs_and_errors(cli, clouds, tmp_path):
    _, dst, _ = clouds
    geo = tmp_path / "geo.las"
    code, _out, err = cli(
        "cloud",
        "transform",
        str(dst),
        str(geo),
        "--to-crs",
        "EPSG:4326",
        "--scales",
        "1e-9,1e-9,1e-4",
        "-q",
    )
    assert code == 0, err
    assert pg.io.cloud_info(geo).crs_name.startswith("EPSG:4326")
    lon, lat = pyproj.Transformer.from_crs(32633, 4326, always_xy=True).transform(
        *pg.io.read_cloud_xyz(dst)[:5, :2].T
    )
    np.testing.assert_allclose(pg.io.read_cloud_xyz(geo)[:5, :2], np.c_[lon, lat], atol=1e-9)
    code, _, err = cli("cloud", "transform", str(dst), str(geo))
    assert code == 2 and "--params" in err
    code, _, err = cli(
        "cloud", "register", str(dst), str(tmp_path / "geo.las"), "--check-every", "1"
    )
    assert code == 2 and "--check-every" in err


def test_crs_convert_geographic_geocentric_enu(cli, tmp_path):
    pts = tmp_path / "p.csv"
    pts.write_text("id,lon,lat,h\na,2.12955,53.80939444,73.0\nb,2.2,53.9,120.5\n")
    code, out, err = cli(
        "crs",
        "convert",
        str(pts),
        "--from",
        "EPSG:4979",
        "--to",
        "EPSG:4978",
        "--cols",
        "lon,lat,h",
    )
    assert code == 0, err
    rows = [r.split(",") for r in out.splitlines() if r and not r.startswith("#")]
    assert rows[0] == ["id", "x", "y", "z"]
    X = pg.crs.geodetic_to_ecef(53.80939444, 2.12955, 73.0)
    np.testing.assert_allclose([float(v) for v in rows[1][1:]], X, atol=1e-6)
    code, out, err = cli(
        "crs",
        "convert",
        str(pts),
        "--from",
        "EPSG:4979",
        "--to",
        "enu",
        "--origin",
        "53.8,2.1,50",
        "--cols",
        "lon,lat,h",
    )
    assert code == 0, err
    rows = [r.split(",") for r in out.splitlines() if r and not r.startswith("#")]
    enu = pg.crs.LocalFrame(53.8, 2.1, 50).from_geodetic(53.80939444, 2.12955, 73.0)[0]
    np.testing.assert_allclose([float(v) for v in rows[1][1:]], enu, atol=1e-6)
    code, out, err = cli(
        "crs", "convert", str(pts), "--from", "EPSG:4979", "--to", "enu", "--cols", "lon,lat,h"
    )
    assert code == 2 and "--origin" in err
    code, out, err = cli(
        "crs", "convert", str(pts), "--from", "EPSG:0", "--to", "EPSG:4978", "--cols", "lon,lat,h"
    )
    assert code == 2 and "EPSG:0" in err


def test_register_statistics_and_report(cli, tmp_path):
    """sigma0 and the standard deviations of the parameters (from the moments, out of core)
    are printed, in --json and in the --report; they equal the in-memory fit's."""
    rng = np.random.default_rng(8)
    x = rng.uniform([0, 0, 0], [400, 300, 30], (3000, 3))
    T = pg.Similarity3D.from_angles(1.00004, 0.01, -0.02, 0.7, [480000.0, 5300000.0, 250.0])
    X = T.apply(x) + rng.normal(0, 0.01, x.shape)
    src, dst = tmp_path / "scan.las", tmp_path / "ref.las"
    pg.io.write_cloud(src, x, scales=(1e-5, 1e-5, 1e-5))
    pg.io.write_cloud(dst, X, scales=(1e-5, 1e-5, 1e-5), crs="EPSG:32633")
    xs, Xs = pg.io.read_cloud_xyz(src), pg.io.read_cloud_xyz(dst)
    ref = pg.absolute_orientation(xs[np.arange(3000) % 10 != 0], Xs[np.arange(3000) % 10 != 0])
    report = tmp_path / "reg.html"
    args = ("cloud", "register", str(src), str(dst), "--check-every", "10", "--chunk-size",
            "700", "--scheduler", "sync")
    code, out, err = cli(*args, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["sigma0"] == pytest.approx(ref.sigma0, rel=1e-6)
    np.testing.assert_allclose(d["std"], np.sqrt(np.diag(ref.covariance)), rtol=1e-6)
    assert d["parameter_names"] == list(ref.parameter_names) and d["redundancy"] == 3 * 2700 - 7
    code, out, err = cli(*args, "--report", str(report), "--angle-unit", "gon")
    assert code == 0, err
    assert f"sigma0 {ref.sigma0:.4g} m" in out and "std. dev." in out and " gon" in out
    assert ", 5300000.0" in out  # the translation to 0.1 mm (it was printed as 5.3e+06)
    html = report.read_text()
    assert "Control and check pairs" in html and "check RMSE" in html and "sigma0" in html
    # an output into a folder that does not exist is refused before the clouds are read
    code, out, err = cli(*args, "--report", str(tmp_path / "no" / "r.html"))
    assert code != 0 and "--report" in err and "does not exist" in err
