"""`cloud register` printed its angles in gon whatever the user wanted (every other
command has --angle-unit, default deg), outside the printed-angle rule (a kappa of -0.7 rad
shown as -44.56 gon, not 355.44 gon), with unlabelled lengths, and called the rigid
transformation --no-scale where `orient absolute` says --rigid."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import photogeom as pg

pytest.importorskip("laspy")
pytest.importorskip("pyproj")


@pytest.fixture
def clouds(tmp_path):
    rng = np.random.default_rng(3)
    x = rng.uniform([0, 0, 0], [400, 300, 30], (500, 3))
    T = pg.Similarity3D.from_angles(1.00004, 0.01, -0.02, -0.7, [480000.0, 5300000.0, 250.0])
    src, dst = tmp_path / "scan.las", tmp_path / "ref.las"
    pg.io.write_cloud(src, x, scales=(1e-4, 1e-4, 1e-4))
    pg.io.write_cloud(dst, T.apply(x), scales=(1e-4, 1e-4, 1e-4), crs="EPSG:32633")
    return src, dst


def _kappa(out: str, unit: str) -> float:
    return float(re.search(rf"kappa \+?(-?[\d.]+) {unit}", out).group(1))


def test_angles_in_angle_unit_by_the_display_rule(cli, clouds):
    src, dst = clouds
    code, out, err = cli("cloud", "register", src, dst, "--scheduler", "sync")
    assert code == 0, err
    assert _kappa(out, "deg") == pytest.approx(360 - math.degrees(0.7), abs=1e-4)
    code, out, err = cli("cloud", "register", src, dst, "--scheduler", "sync",
                         "--angle-unit", "gon")
    assert code == 0, err
    assert _kappa(out, "gon") == pytest.approx(400 - 0.7 * 200 / math.pi, abs=1e-4)


def test_lengths_carry_the_unit_of_the_target_crs(cli, clouds):
    src, dst = clouds
    code, out, err = cli("cloud", "register", src, dst, "--scheduler", "sync",
                         "--check-every", "5")
    assert code == 0, err
    assert re.search(r"translation [-+\de., ]+ m\n", out)
    assert re.search(r"control RMSE [\de.-]+ m ", out) and "max " in out


def test_rigid_is_the_option_and_no_scale_its_old_name(cli, clouds):
    src, dst = clouds
    outs = []
    for flag in ("--rigid", "--no-scale"):
        code, out, err = cli("cloud", "register", src, dst, "--scheduler", "sync", flag)
        assert code == 0, err
        outs.append(out)
    assert outs[0] == outs[1] and "scale 1.0000000000" in outs[0]
    code, out, _ = cli("cloud", "register", "--help")
    assert "--rigid" in out and "--no-scale" not in out
