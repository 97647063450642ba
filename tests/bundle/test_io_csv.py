"""CSV block folders: round trips of everything a block holds, units, Metashape XML starting
cameras, conversions between formats, named errors with file and line, atomic writes."""

from __future__ import annotations

import csv
import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.bundle import (
    Block,
    projected_pixels,
    read_bal,
    read_colmap,
    read_csv_block,
    reprojection_residuals,
    write_bal,
    write_colmap,
    write_csv_block,
)
from photogeom.camera.metashape import MetashapeCalibration, write_metashape_xml
from photogeom.errors import FileFormatError, InputError


def _rich_block(rng, *, n_img=6, n_pt=15) -> Block:
    cams = {
        "FC300S": MetashapeCalibration(
            4000, 3000, 2300.5, cx=10.25, cy=-7.5, k1=-0.1, k2=0.05, k3=-0.01, p1=1e-4, p2=-2e-4
        ),
        "ILCE 7RM2": MetashapeCalibration(7952, 5304, 7800.0, k1=0.01, k4=1e-5, b1=0.75, b2=-0.25),
    }
    ids = [f"DJI_{k:04d}.JPG" for k in range(n_img)]
    group = ["FC300S" if k % 2 == 0 else "ILCE 7RM2" for k in range(n_img)]
    ext = np.column_stack(
        [
            rng.uniform(500000, 500100, n_img),
            rng.uniform(4e6, 4e6 + 100, n_img),
            rng.uniform(90, 110, n_img),
            rng.uniform(-0.1, 0.1, (n_img, 2)),
            rng.uniform(-math.pi, math.pi, n_img),
        ]
    )
    pts = np.column_stack(
        [
            rng.uniform(499990, 500110, n_pt),
            rng.uniform(4e6 - 10, 4e6 + 110, n_pt),
            rng.uniform(0, 10, n_pt),
        ]
    )
    role = np.array(["tie"] * n_pt, dtype="<U7")
    role[:3] = "control"
    role[3] = "check"
    psig = np.full((n_pt, 3), np.nan)
    psig[:4] = [0.02, 0.02, 0.05]
    gnss = ext[:, :3] + rng.normal(0, 0.05, (n_img, 3))
    gnss[1] = np.nan
    imu = ext[:, 3:] + rng.normal(0, 1e-3, (n_img, 3))
    imu[2:4] = np.nan
    ii, jj = np.meshgrid(np.arange(n_img), np.arange(n_pt), indexing="ij")
    off = np.zeros((n_img, 3))
    off[::2] = rng.normal(0, 1.0, (len(off[::2]), 3))
    b = Block.from_arrays(
        cameras=cams,
        image_ids=ids,
        image_camera=group,
        exterior=ext,
        point_ids=np.arange(100, 100 + n_pt),
        xyz=pts,
        obs_image_ids=np.array(ids)[ii.ravel()],
        obs_point_ids=(100 + jj).ravel(),
        uv=rng.uniform(0, 3000, (n_img * n_pt, 2)),
        sigma=rng.uniform(0.3, 1.5, n_img * n_pt),
        role=role,
        point_sigma=psig,
        gnss=gnss,
        gnss_sigma=[0.05, 0.05, 0.1],
        imu=imu,
        imu_sigma=[1e-3, 1e-3, 2e-3],
        calibration_offset=off,
        free={"FC300S": ("f", "cx", "cy", "k1", "k2", "k3", "p1", "p2"), "ILCE 7RM2": ("f",)},
        image_variant={"FC300S": ("f", "cx", "cy")},
        crs="EPSG:32633",
    )
    return b


def _assert_identical(a: Block, b: Block, tol=1e-12):
    for name in ("camera_ids", "image_ids", "point_ids", "role"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert type(a.image_ids[0].item()) is type(b.image_ids[0].item())
    assert type(a.point_ids[0].item()) is type(b.point_ids[0].item())
    np.testing.assert_array_equal(a.image_camera, b.image_camera)
    assert a.calibrations == b.calibrations
    np.testing.assert_allclose(a.exterior, b.exterior, rtol=tol, atol=tol)
    for name in ("calibration_offset", "gnss", "gnss_sigma", "imu", "imu_sigma", "xyz"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=tol, atol=tol)
    np.testing.assert_array_equal(a.point_sigma, b.point_sigma)
    o, p = a.observations, b.observations
    np.testing.assert_array_equal(o.image_ids, p.image_ids)
    np.testing.assert_array_equal(o.point_ids, p.point_ids)
    np.testing.assert_array_equal(o.uv, p.uv)
    np.testing.assert_array_equal(o.sigma, p.sigma)
    assert dict(a.free) == dict(b.free)
    assert dict(a.image_variant) == dict(b.image_variant)
    assert a.crs == b.crs


@pytest.mark.parametrize("unit", ["deg", "gon", "rad"])
def test_round_trip_of_everything(tmp_path, unit):
    b = _rich_block(np.random.default_rng(1))
    write_csv_block(b, tmp_path, angle_unit=unit)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["cameras.csv", "images.csv", "points.csv", "observations.csv"]
    )
    back = read_csv_block(tmp_path)
    _assert_identical(b, back)


def test_angle_columns_carry_their_unit(tmp_path):
    b = _rich_block(np.random.default_rng(2))
    write_csv_block(b, tmp_path)
    rows = list(csv.DictReader(line for line in open(tmp_path / "images.csv") if line[0] != "#"))
    assert float(rows[0]["kappa_deg"]) == pytest.approx(math.degrees(b.exterior[0, 5]), abs=1e-12)
    assert float(rows[0]["imu_somega_deg"]) == pytest.approx(math.degrees(1e-3), abs=1e-15)
    assert rows[1]["gnss_X"] == ""  # image without GNSS
    assert rows[0]["X0"] == repr(float(b.exterior[0, 0]))


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_round_trip_random(tmp_path_factory, seed):
    b = _rich_block(np.random.default_rng(seed), n_img=3, n_pt=5)
    d = tmp_path_factory.mktemp("csv")
    write_csv_block(b, d)
    _assert_identical(b, read_csv_block(d))


def test_a_folder_written_by_hand(tmp_path):
    (tmp_path / "cameras.csv").write_text("camera,width,height,f,k1\n1,4000,3000,2300,-0.1\n")
    (tmp_path / "images.csv").write_text(
        "# two images\n"
        "id,camera,X0,Y0,Z0,omega_gon,phi_gon,kappa_gon\n"
        "1,1,0,0,100,0,0,0\n"
        "2,1,30,0,100,0,0,100\n"
    )
    (tmp_path / "points.csv").write_text("id,role,X,Y,Z\nA,tie,10,5,0\nB,tie,20,-5,0\n")
    (tmp_path / "observations.csv").write_text(
        "image_id,point_id,u,v\n1,A,2100,1700\n1,B,2400,1300\n2,A,1900,1500\n2,B,1000,1200\n"
    )
    b = read_csv_block(tmp_path, sigma=0.7)
    assert b.images[2].exterior.kappa == pytest.approx(math.pi / 2, abs=1e-15)
    assert list(b.points) == ["A", "B"] and b.image_ids.dtype.kind == "i"
    np.testing.assert_array_equal(b.observations.sigma, 0.7)
    assert b.free[1] == pg.bundle.DEFAULT_FREE
    assert b.cameras[1].k1 == -0.1 and b.cameras[1].cx == 0.0
    # a spreadsheet export with semicolons
    (tmp_path / "cameras.csv").write_text("camera;width;height;f;k1\n1;4000;3000;2300;-0.1\n")
    assert read_csv_block(tmp_path).cameras[1].k1 == -0.1
    # ids that are not canonical integers stay text
    (tmp_path / "points.csv").write_text("id,role,X,Y,Z\n07,tie,10,5,0\n8,tie,20,-5,0\n")
    (tmp_path / "observations.csv").write_text(
        "image_id,point_id,u,v\n1,07,2100,1700\n1,8,2400,1300\n2,07,1900,1500\n2,8,1000,1200\n"
    )
    assert list(read_csv_block(tmp_path).points) == ["07", "8"]


def test_metashape_xml_as_starting_camera(tmp_path):
    b = _rich_block(np.random.default_rng(3))
    write_csv_block(b, tmp_path)
    start = MetashapeCalibration(4000, 3000, 2350.0, k1=-0.08)
    write_metashape_xml(start, tmp_path / "fc300s.xml")
    got = read_csv_block(tmp_path, calibrations={"FC300S": tmp_path / "fc300s.xml"})
    assert got.cameras["FC300S"] == start
    assert got.cameras["ILCE 7RM2"] == b.cameras["ILCE 7RM2"]
    assert got.free["FC300S"] == b.free["FC300S"]
    # without cameras.csv every camera comes from XML (default free parameters)
    os.remove(tmp_path / "cameras.csv")
    other = MetashapeCalibration(7952, 5304, 7700.0)
    got = read_csv_block(
        tmp_path, calibrations={"FC300S": tmp_path / "fc300s.xml", "ILCE 7RM2": other}
    )
    assert got.cameras["ILCE 7RM2"] == other
    with pytest.raises(FileFormatError, match=r"no cameras\.csv"):
        read_csv_block(tmp_path)
    with pytest.raises(FileFormatError, match=r"camera 'ILCE 7RM2' is not one of the camera"):
        read_csv_block(tmp_path, calibrations={"FC300S": start})


def test_conversions_between_formats_keep_the_projection(tmp_path):
    """BAL -> CSV -> COLMAP -> BAL: the same residuals and the same BAL numbers."""
    b = read_bal(pg.datasets.path("dubrovnik-3-7"))
    write_csv_block(b, tmp_path / "csv")
    c = read_csv_block(tmp_path / "csv")
    write_colmap(c, tmp_path / "colmap")
    d = read_colmap(tmp_path / "colmap", image_key="id")
    write_bal(d, tmp_path / "back.txt")
    e = read_bal(tmp_path / "back.txt")
    for blk in (c, d, e):
        uv = projected_pixels(blk)[0]
        order = np.lexsort((blk.observations.point_ids, blk.observations.image_ids))
        ref = np.lexsort((b.observations.point_ids, b.observations.image_ids))
        np.testing.assert_allclose(uv[order], projected_pixels(b)[0][ref], atol=1e-9)
        np.testing.assert_allclose(
            reprojection_residuals(blk)[order], reprojection_residuals(b)[ref], atol=1e-9
        )


# --- errors --------------------------------------------------------------------------------


def _folder(tmp_path, **files):
    base = {
        "cameras.csv": "camera,width,height,f\nc,100,80,90\n",
        "images.csv": "id,camera,X0,Y0,Z0,omega_deg,phi_deg,kappa_deg\n1,c,0,0,10,0,0,0\n",
        "points.csv": "id,role,X,Y,Z,sX,sY,sZ\n1,tie,0,0,0,,,\n2,control,1,1,0,0.01,0.01,0.02\n",
        "observations.csv": "image_id,point_id,u,v,sigma\n1,1,49.5,39.5,0.5\n1,2,58,31,0.5\n",
    }
    base.update({k.replace("_", "."): v for k, v in files.items()})
    for name, text in base.items():
        if text is not None:
            (tmp_path / name).write_text(text)
    return tmp_path


def test_minimal_error_free_folder(tmp_path):
    b = read_csv_block(_folder(tmp_path))
    assert b.n_observations == 2 and b.points[2].role == "control"


@pytest.mark.parametrize(
    ("files", "match"),
    [
        (
            {"observations_csv": "image_id,point_id,u,v,sigma\n1,1,49.5,x,0.5\n"},
            r"observations.csv, line 2: column 'v': 'x' is not a number",
        ),
        (
            {"observations_csv": "image_id,point_id,u,v\n1,1,49.5,39.5\n\n# c\n1,9,1,1\n"},
            r"observations.csv, line 5: point_id '9' is not one of the point",
        ),
        (
            {"observations_csv": "image_id,point_id,u,v\n1,1,49.5,39.5\nq,1,1,1\n"},
            r"observations.csv, line 3: image_id 'q' is not one of the image",
        ),
        (
            {"images_csv": "id,camera,X0,Y0,Z0,omega,phi,kappa\n1,c,0,0,10,0,0,0\n"},
            r"images.csv: angle column\(s\) omega, phi, kappa not found: name them with their "
            r"unit \(omega_deg",
        ),
        (
            {"images_csv": "id,camera,X0,Y0,Z0,omega_deg,phi_deg,kappa_deg\n1,d,0,0,10,0,0,0\n"},
            r"images.csv, line 2: camera 'd' is not one of the camera ids",
        ),
        (
            {"images_csv": "id,camera,X0,Y0,Z0,omega_deg,phi_deg,kappa_deg\n1,c,0,,10,0,0,0\n"},
            r"images.csv, line 2: column 'Y0' is empty",
        ),
        (
            {"points_csv": "id,role,X,Y,Z\n1,tie,0,0,0\n2,gcp,1,1,0\n"},
            r"points.csv, line 3: role 'gcp' is not tie, control or check",
        ),
        (
            {"points_csv": "id,role,X,Y,Z,sX,sY,sZ\n1,tie,0,0,0,,,\n2,check,1,1,0,,,\n"},
            r"points.csv, line 3: check point 2 needs positive sX, sY, sZ",
        ),
        (
            {"points_csv": "id,role,X,Y,Z\n1,tie,0,0,0\n2,tie,1,1\n"},
            r"points.csv, line 3: 4 field\(s\) but the header has 5",
        ),
        ({"points_csv": None}, r"points.csv: no such file"),
        (
            {"cameras_csv": "camera,width,height,f\nc,100,80,-90\n"},
            r"cameras.csv, line 2: camera 'c': focal length must be > 0",
        ),
        (
            {"cameras_csv": "camera,width,height,f,free\nc,100,80,90,f k9\n"},
            r"free of camera 'c': unknown parameter\(s\) \['k9'\]",
        ),
        (
            {"observations_csv": "image_id,point_id,u,v,sigma\n1,1,49.5,39.5,0\n"},
            r"observations.csv, line 2: sigma must be positive",
        ),
        (
            {"points_csv": "id,role,X,Y,Z\n1,tie,0,0,0\n1,tie,1,1,0\n"},
            r"points.csv, line 3: id '1' appears twice \(first on line 2\)",
        ),
    ],
)
def test_named_errors(tmp_path, files, match):
    with pytest.raises(FileFormatError, match=match):
        read_csv_block(_folder(tmp_path, **files))


def test_bad_angle_unit_and_missing_folder(tmp_path):
    b = read_csv_block(_folder(tmp_path))
    with pytest.raises(InputError, match="angle_unit"):
        write_csv_block(b, tmp_path / "out", angle_unit="arcsec")
    with pytest.raises(FileFormatError, match="not a directory"):
        read_csv_block(tmp_path / "missing")


def test_write_is_atomic(tmp_path, monkeypatch):
    b = _rich_block(np.random.default_rng(4))
    write_csv_block(b, tmp_path)
    before = {p.name: p.read_text() for p in tmp_path.iterdir()}
    calls = []

    def failing_replace(src, dst):
        calls.append(dst)
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", failing_replace)
    changed = b.with_observations(uv=b.observations.uv + 1.0)
    with pytest.raises(OSError, match="disk full"):
        write_csv_block(changed, tmp_path)
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == before  # no temp left


def test_read_and_write_block_by_path(tmp_path):
    from photogeom.bundle import detect_format, read_block, write_block

    b = read_block(pg.datasets.path("dubrovnik-3-7"))
    write_block(b, tmp_path / "p.bal.bz2")
    write_block(b, tmp_path / "model", kind="colmap")
    write_block(b, tmp_path / "csv", kind="CSV")
    assert [detect_format(tmp_path / n) for n in ("p.bal.bz2", "model", "csv")] == [
        "bal",
        "colmap",
        "csv",
    ]
    for name, opts in (("p.bal.bz2", {}), ("model", {"image_key": "id"}), ("csv", {})):
        c = read_block(tmp_path / name, **opts)
        o, ob = c.observations, b.observations  # COLMAP reads image by image
        k1 = np.lexsort((o.point_ids, o.image_ids))
        k0 = np.lexsort((ob.point_ids, ob.image_ids))
        np.testing.assert_allclose(
            reprojection_residuals(c)[k1], reprojection_residuals(b)[k0], atol=1e-9
        )
    write_block(c, tmp_path / "csv")  # an existing folder keeps its format
    with pytest.raises(InputError, match="say which format"):
        write_block(b, tmp_path / "new_folder")
    with pytest.raises(InputError, match="unknown block format 'ply'"):
        read_block(tmp_path / "csv", kind="ply")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileFormatError, match="neither a COLMAP text model"):
        read_block(tmp_path / "empty")
