"""Images adjusted near phi = +-90 degrees: the standard deviations of omega and kappa are
inflated by 1 / cos(phi) and nearly fully correlated there; the result says so."""

import re

import numpy as np

import photogeom as pg
from photogeom.bundle import bundle_adjust
from photogeom.bundle._angles import opk_from_rotations

# object x' = Q x turns the nadir images' viewing direction onto the object x axis (phi 90)
Q = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


def _blocks():
    sim = pg.simulate.uav_block(
        "FC300S", seed=3, strips=2, images_per_strip=4, gnss_sigma=None, imu_sigma_deg=None,
        attitude_jitter_deg=0.2, initial_camera="truth", local_field=0.0,
    )  # fmt: skip
    b = sim.block
    ex = np.array(b.exterior, dtype=float)
    ex[:, :3] = ex[:, :3] @ Q.T
    ex[:, 3:] = opk_from_rotations(b.rotations() @ Q.T)
    turned = b.replace(
        exterior=ex,
        xyz=np.asarray(b.xyz) @ Q.T,
        point_sigma=np.abs(np.asarray(b.point_sigma) @ Q.T),
    )
    return b, turned


def test_images_near_gimbal_lock_are_named_with_the_inflation_of_their_angle_std():
    nadir, turned = _blocks()
    f0 = bundle_adjust(nadir, free=())
    f1 = bundle_adjust(turned, free=())
    assert not any("gimbal lock" in n for n in f0.notes)
    # the same block in a turned object system: the same fit, but omega and kappa std
    # 3-47 degrees where the nadir block's are at most 0.05; before, no word of it
    assert abs(f1.sigma0 / f0.sigma0 - 1) < 1e-8
    std_ok = np.degrees(f1.exterior_std[:, [3, 5]])
    assert std_ok.min() > 1.0 > 0.1 > np.degrees(f0.exterior_std[:, 3:]).max()
    note = [n for n in f1.notes if "gimbal lock" in n]
    assert len(note) == 1
    assert note[0].startswith("8 image(s) (")
    own = float(re.search(r"own precision \(([\d.e+-]+) deg", note[0]).group(1))
    # the attitude's own precision does not depend on the object system: the nadir block's
    # largest standard deviation of a small rotation
    cov = np.stack([f0.image_covariance(i)[3:, 3:] for i in nadir.image_ids.tolist()])
    assert abs(own / np.degrees(np.sqrt(np.linalg.eigvalsh(cov).max())) - 1) < 0.05
    assert re.search(r"correlated [+-]0\.99\d\d|correlated [+-]1\.0000", note[0])
    assert any("gimbal lock" in line for line in f1.summary().splitlines())
