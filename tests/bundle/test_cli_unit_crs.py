"""``bundle adjust --unit`` that contradicts the block's CRS is refused.

Before, ``--unit ft`` on a block in EPSG:25832 (metres) printed and wrote every length
(GSD, check-point RMSE, standard deviations) labelled in feet, the numbers still metres;
``transform estimate`` and ``orient absolute`` refuse such a unit.
"""

from __future__ import annotations

import pytest

import photogeom as pg

pytest.importorskip("pyproj")


@pytest.fixture(scope="module")
def block_dir(tmp_path_factory):
    sim = pg.simulate.uav_block(
        "FC300S", seed=2, strips=2, images_per_strip=3, tie_points_per_image=40
    )
    d = tmp_path_factory.mktemp("utm")
    pg.bundle.write_csv_block(sim.block.replace(crs="EPSG:25832"), d)
    return d


def test_a_unit_against_the_recorded_crs_is_refused(block_dir, cli, tmp_path):
    code, out, err = cli(
        "bundle", "adjust", block_dir, "--unit", "ft", "--result", tmp_path / "r.json"
    )
    assert code == 2, (out, err)
    assert err.startswith("error: the block's CRS (points.csv '# crs:' line) EPSG:25832")
    assert "has coordinates in m, but --unit is ft: leave --unit out" in err
    assert not (tmp_path / "r.json").exists()
    # the CRS's own unit, or none, is taken
    code, out, err = cli("bundle", "adjust", block_dir, "--unit", "m")
    assert code == 0, err
    assert " m per px" in out


def test_a_unit_against_the_crs_option_is_refused(block_dir, cli, tmp_path):
    plain = tmp_path / "plain"
    pg.bundle.write_csv_block(pg.bundle.read_csv_block(block_dir).replace(crs=None), plain)
    code, _, err = cli("bundle", "adjust", plain, "--crs", "EPSG:2263", "--unit", "m")
    assert code == 2
    assert (
        err.startswith("error: --crs EPSG:2263")
        and "has coordinates in ftUS, but --unit is m" in err
    )
    # without a CRS the unit is the user's word for the coordinates
    code, out, err = cli("bundle", "adjust", plain, "--unit", "mm")
    assert code == 0, err
    assert " mm per px" in out
