"""The comment lines of a CSV block folder name the unit of every number they describe.

Before, ``points.csv`` said "object coordinates; sX, sY, sZ: standard deviations of surveyed
points" and ``images.csv`` "projection centre and omega, phi, kappa in deg": no length unit
for the coordinates, their standard deviations or the GNSS columns. Now the length unit is
the block's CRS's (``ftUS`` for EPSG:2263), ``m`` without a CRS; the reader ignores these
comments, so folders written before read as they did.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.bundle import read_csv_block, write_csv_block


@pytest.fixture(scope="module")
def block():
    sim = pg.simulate.uav_block(
        "FC300S", seed=1, strips=2, images_per_strip=3, tie_points_per_image=20
    )
    b = sim.block
    assert np.isfinite(b.gnss).any() and np.isfinite(b.imu).any()
    return b


def _comments(path) -> list[str]:
    return [s[1:].strip() for s in path.read_text().splitlines() if s.startswith("#")]


def _same(a, b):
    np.testing.assert_array_equal(a.xyz, b.xyz)
    np.testing.assert_array_equal(a.exterior[:, :3], b.exterior[:, :3])
    np.testing.assert_allclose(a.exterior[:, 3:], b.exterior[:, 3:], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(a.gnss, b.gnss)
    np.testing.assert_array_equal(a.gnss_sigma, b.gnss_sigma)
    np.testing.assert_array_equal(a.point_sigma, b.point_sigma)
    np.testing.assert_array_equal(a.observations.uv, b.observations.uv)
    assert a.crs == b.crs


@pytest.mark.parametrize(
    ("crs", "pyproj_unit", "label"),
    [(None, None, "m"), ("EPSG:2263", "US survey foot", "ftUS"), ("EPSG:25832", "metre", "m")],
)
def test_comments_name_the_length_unit(block, tmp_path, crs, pyproj_unit, label):
    if crs is not None:
        import pyproj

        # the unit the label stands for, as PROJ names the CRS's first axis
        assert pyproj.CRS(crs).axis_info[0].unit_name == pyproj_unit
        block = block.replace(crs=crs)
    write_csv_block(block, tmp_path)
    (images,) = _comments(tmp_path / "images.csv")  # one line, as before
    parts = images.split("; ")
    assert parts[0].startswith(f"exterior orientation: projection centre X0, Y0, Z0 in {label}, ")
    assert "omega, phi, kappa in deg" in parts[0]
    assert parts[1].startswith("gnss_X") and parts[1].endswith(f"standard deviations in {label}")
    assert parts[2].startswith("imu_") and parts[2].endswith("in deg")
    points = _comments(tmp_path / "points.csv")
    assert points[0] == (
        f"object coordinates X, Y, Z in {label}; sX, sY, sZ: standard deviations of surveyed "
        f"points in {label}"
    )
    assert "sigma in pixels" in _comments(tmp_path / "observations.csv")[0]
    assert "in pixels" in _comments(tmp_path / "cameras.csv")[0]
    # the written folder reads back to the block, its CRS from the crs: line
    _same(read_csv_block(tmp_path), block)


def test_gon_and_offsets_are_named(block, tmp_path):
    off = np.zeros((block.n_images, 3))
    off[0] = [1.5, -0.25, 0.5]
    b = block.replace(calibration_offset=off)
    write_csv_block(b, tmp_path, angle_unit="gon")
    (images,) = _comments(tmp_path / "images.csv")
    assert "omega, phi, kappa in gon" in images
    assert "; df, dcx, dcy: per-image offsets of f, cx, cy in pixels; " in images
    assert "its standard deviations in gon" in images
    np.testing.assert_array_equal(read_csv_block(tmp_path).calibration_offset, off)


def test_a_geographic_or_unknown_crs_claims_no_unit(block, tmp_path):
    # EPSG:4326 has degrees and no height axis: no one length unit to name
    write_csv_block(block.replace(crs="EPSG:4326"), tmp_path)
    points = _comments(tmp_path / "points.csv")
    assert points[0].startswith(
        "object coordinates X, Y, Z in the unit of the CRS on the crs: line of points.csv; "
    )
    assert "crs: EPSG:4326" in points
    assert " in m" not in " ".join(_comments(tmp_path / "images.csv"))


def test_a_folder_with_the_former_comments_reads_the_same(block, tmp_path):
    new = tmp_path / "new"
    write_csv_block(block.replace(crs="EPSG:25832"), new)
    old = tmp_path / "old"
    old.mkdir()
    former = {
        "images.csv": [
            "# exterior orientation: projection centre and omega, phi, kappa in deg "
            "(M = M3(kappa) M2(phi) M1(omega), object -> image)"
        ],
        "points.csv": [
            "# object coordinates; sX, sY, sZ: standard deviations of surveyed points",
            "# crs: EPSG:25832",
        ],
    }
    for f in new.iterdir():
        lines = f.read_text().splitlines()
        if f.name in former:
            lines = former[f.name] + [s for s in lines if not s.startswith("#")]
        (old / f.name).write_text("\n".join(lines) + "\n")
    _same(read_csv_block(old), read_csv_block(new))
