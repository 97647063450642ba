"""BAL files: conventions against an independent implementation of BAL's formula and against
GTSAM's reader, round trips, bz2, named errors, atomic writes."""

from __future__ import annotations

import bz2
import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import photogeom as pg
from photogeom.bundle import Block, projected_pixels, read_bal, reprojection_residuals, write_bal
from photogeom.bundle.io_bal import ImageSizeWarning
from photogeom.camera.metashape import MetashapeCalibration
from photogeom.errors import FileFormatError, InputError

DUBROVNIK = pg.datasets.path("dubrovnik-3-7")


def _rodrigues(r):
    """Rotation matrix of an axis-angle vector, written out (Rodrigues' formula)."""
    r = np.asarray(r, dtype=float)
    theta = math.sqrt(float(r @ r))
    if theta < 1e-300:
        return np.eye(3)
    k = r / theta
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(theta) * K + (1 - math.cos(theta)) * (K @ K)


def _parse_bal(path):
    """A plain reader of the BAL layout (one token at a time), independent of read_bal."""
    tok = open(path).read().split()
    m, p, n = int(tok[0]), int(tok[1]), int(tok[2])
    k = 3
    obs = []
    for _ in range(n):
        obs.append((int(tok[k]), int(tok[k + 1]), float(tok[k + 2]), float(tok[k + 3])))
        k += 4
    cams = [[float(t) for t in tok[k + 9 * c : k + 9 * c + 9]] for c in range(m)]
    k += 9 * m
    pts = [[float(t) for t in tok[k + 3 * j : k + 3 * j + 3]] for j in range(p)]
    return obs, cams, pts


def _bal_project(cam, X):
    """BAL's documented projection: P = R X + t, p = -P / P_z, f r(p) p."""
    R = _rodrigues(cam[:3])
    P = R @ np.asarray(X) + np.asarray(cam[3:6])
    p = -P[:2] / P[2]
    n2 = float(p @ p)
    r = 1.0 + cam[7] * n2 + cam[8] * n2 * n2
    return cam[6] * r * p


def test_bundled_file_counts_and_values():
    b = read_bal(DUBROVNIK)
    assert (b.n_images, b.n_points, b.n_observations) == (3, 7, 19)
    obs, cams, pts = _parse_bal(DUBROVNIK)
    c0 = b.cameras[0]
    assert c0.f == cams[0][6] and c0.k1 == cams[0][7] and c0.k2 == cams[0][8]
    assert (c0.cx, c0.cy, c0.k3, c0.p1, c0.b1) == (0.0, 0.0, 0.0, 0.0, 0.0)
    assert b.free[0] == ("f", "k1", "k2")
    np.testing.assert_array_equal(b.xyz, np.array(pts))
    # one group per image; image size: smallest even sizes holding every observation
    assert list(b.cameras) == [0, 1, 2]
    xy = np.array([o[2:] for o in obs])
    assert c0.width == 2 * math.ceil(np.abs(xy[:, 0]).max())
    assert c0.height == 2 * math.ceil(np.abs(xy[:, 1]).max())
    # pixel convention: u = x + (w - 1) / 2, v = (h - 1) / 2 - y
    np.testing.assert_array_equal(b.observations.uv[:, 0], xy[:, 0] + (c0.width - 1) / 2)
    np.testing.assert_array_equal(b.observations.uv[:, 1], (c0.height - 1) / 2 - xy[:, 1])


def test_projection_matches_bal_formula():
    """Every observation's projection through the block equals BAL's own formula."""
    b = read_bal(DUBROVNIK)
    obs, cams, pts = _parse_bal(DUBROVNIK)
    uv, depth = projected_pixels(b)
    assert np.all(depth > 0)
    w, h = b.cameras[0].width, b.cameras[0].height
    for k, (ci, pj, _x, _y) in enumerate(obs):
        xb, yb = _bal_project(cams[ci], pts[pj])
        assert uv[k, 0] - (w - 1) / 2 == pytest.approx(xb, abs=1e-9)
        assert (h - 1) / 2 - uv[k, 1] == pytest.approx(yb, abs=1e-9)
    # residuals: computed - observed, BAL's x and -y
    res = reprojection_residuals(b)
    bal_res = np.array([_bal_project(cams[ci], pts[pj]) - (x, y) for ci, pj, x, y in obs])
    np.testing.assert_allclose(res[:, 0], bal_res[:, 0], atol=1e-9)
    np.testing.assert_allclose(res[:, 1], -bal_res[:, 1], atol=1e-9)


def test_exterior_orientation_convention():
    """BAL's camera frame is the photogrammetric image system: M = R, X0 = -R^T t."""
    b = read_bal(DUBROVNIK)
    _, cams, _ = _parse_bal(DUBROVNIK)
    for i, cam in enumerate(cams):
        R = _rodrigues(cam[:3])
        e = b.images[i].exterior
        np.testing.assert_allclose(pg.opk_matrix(e.omega, e.phi, e.kappa), R, atol=1e-14)
        np.testing.assert_allclose([e.X0, e.Y0, e.Z0], -R.T @ np.array(cam[3:6]), atol=1e-13)


def _gtsam_residuals(data):
    """GTSAM's projection of every track measurement, minus the measurement."""
    out = []
    for j in range(data.numberTracks()):
        t = data.track(j)
        for k in range(t.numberMeasurements()):
            ci, meas = t.measurement(k)
            cam = data.camera(ci)
            out.append((ci, j, cam.project(t.point3()) - meas))
    return out


def test_against_gtsam_reader():
    gtsam = pytest.importorskip("gtsam")
    data = gtsam.SfmData.FromBalFile(str(DUBROVNIK))
    b = read_bal(DUBROVNIK)
    res = reprojection_residuals(b)
    key = {
        (int(i), int(j)): r
        for i, j, r in zip(b.observations.image_ids, b.observations.point_ids, res)
    }
    g = _gtsam_residuals(data)
    assert len(g) == b.n_observations
    for ci, j, r in g:  # GTSAM keeps x and flips y down, as photogeom's v
        np.testing.assert_allclose(key[(ci, j)], r, atol=1e-9)


def test_gtsam_written_bal_of_a_bundler_block(tmp_path):
    """GTSAM's Balbianello (5 images, 544 tracks, Bundler) written as BAL by GTSAM."""
    gtsam = pytest.importorskip("gtsam")
    try:
        src = gtsam.findExampleDataFile("Balbianello.out")
    except Exception:  # pragma: no cover - wheels without data
        pytest.skip("gtsam ships no Balbianello.out")
    data = gtsam.SfmData.FromBundlerFile(src)
    path = tmp_path / "balbianello.bal"
    gtsam.writeBAL(str(path), data)
    b = read_bal(path)
    assert (b.n_images, b.n_points) == (5, 544)
    back = gtsam.SfmData.FromBalFile(str(path))
    res = reprojection_residuals(b)
    key = {
        (int(i), int(j)): r
        for i, j, r in zip(b.observations.image_ids, b.observations.point_ids, res)
    }
    g = _gtsam_residuals(back)
    assert len(g) == b.n_observations
    worst = max(float(np.max(np.abs(key[(ci, j)] - r))) for ci, j, r in g)
    assert worst < 1e-9


def _assert_same_block(a: Block, b: Block, tol=1e-12):
    assert a.n_images == b.n_images and a.n_points == b.n_points
    np.testing.assert_array_equal(a.image_ids, b.image_ids)
    np.testing.assert_array_equal(a.point_ids, b.point_ids)
    np.testing.assert_array_equal(a.observations.image_ids, b.observations.image_ids)
    np.testing.assert_array_equal(a.observations.point_ids, b.observations.point_ids)
    scale = max(1.0, float(np.abs(a.exterior[:, :3]).max(initial=0)))
    np.testing.assert_allclose(a.exterior[:, :3], b.exterior[:, :3], rtol=0, atol=tol * scale)
    np.testing.assert_allclose(a.rotations(), b.rotations(), rtol=0, atol=tol)
    np.testing.assert_allclose(a.xyz, b.xyz, rtol=tol, atol=0)
    np.testing.assert_allclose(a.observations.uv, b.observations.uv, rtol=0, atol=tol * 1e3)
    np.testing.assert_allclose(a.calibration_matrix(), b.calibration_matrix(), rtol=tol)
    assert dict(a.free) == dict(b.free)


def test_file_round_trip_reproduces_the_numbers(tmp_path):
    b = read_bal(DUBROVNIK)
    out = tmp_path / "again.txt"
    write_bal(b, out)
    o1, c1, p1 = _parse_bal(DUBROVNIK)
    o2, c2, p2 = _parse_bal(out)
    assert [o[:2] for o in o1] == [o[:2] for o in o2]
    np.testing.assert_allclose([o[2:] for o in o2], [o[2:] for o in o1], rtol=1e-15, atol=1e-12)
    np.testing.assert_allclose(p2, p1, rtol=0, atol=0)
    # the rotation vector passes through omega, phi, kappa: equal to rounding
    np.testing.assert_allclose(c2, c1, rtol=1e-12, atol=1e-15)
    _assert_same_block(b, read_bal(out))


def test_bz2_read_and_write(tmp_path):
    raw = DUBROVNIK.read_bytes()
    comp = tmp_path / "problem.bz2"
    comp.write_bytes(bz2.compress(raw))
    b = read_bal(comp)
    _assert_same_block(b, read_bal(DUBROVNIK), tol=0)
    out = tmp_path / "written.txt.bz2"
    write_bal(b, out)
    assert out.read_bytes()[:3] == b"BZh"
    _assert_same_block(b, read_bal(out))


def _bal_block(rng, m=4, p=12, image_size=(4000, 3000)):
    """A BAL-type block (one camera per image, f, k1, k2) seeing points in front."""
    pts = rng.uniform([-20, -20, -5], [20, 20, 5], size=(p, 3))
    ext, cams = [], {}
    for i in range(m):
        om, ph, ka = rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-3, 3)
        ext.append([*rng.uniform(-5, 5, 2), 60 + rng.uniform(-5, 5), om, ph, ka])
        cams[i] = MetashapeCalibration(
            *image_size, rng.uniform(2000, 4000), k1=rng.normal(0, 0.05), k2=rng.normal(0, 0.01)
        )
    ii, jj = np.meshgrid(np.arange(m), np.arange(p), indexing="ij")
    b0 = Block.from_arrays(
        cameras=cams,
        image_ids=range(m),
        image_camera=range(m),
        exterior=ext,
        point_ids=range(p),
        xyz=pts,
        obs_image_ids=ii.ravel(),
        obs_point_ids=jj.ravel(),
        uv=np.zeros((m * p, 2)),
        sigma=1.0,
        free=("f", "k1", "k2"),
    )
    uv, _ = projected_pixels(b0)
    return b0.with_observations(uv=uv + rng.normal(0, 0.5, uv.shape))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_round_trip_random_blocks(tmp_path_factory, seed):
    rng = np.random.default_rng(seed)
    b = _bal_block(rng)
    path = tmp_path_factory.mktemp("bal") / "b.txt"
    write_bal(b, path)
    back = read_bal(path, image_size=(4000, 3000))
    _assert_same_block(b, back)
    np.testing.assert_allclose(reprojection_residuals(back), reprojection_residuals(b), atol=1e-9)


def test_principal_point_off_centre_is_written_from_the_principal_point(tmp_path):
    """BAL measures from the principal point: a fixed offset cx, cy is written exactly."""
    rng = np.random.default_rng(3)
    b = _bal_block(rng)
    shifted = b.with_calibrations(
        {
            g: MetashapeCalibration(4000, 3000, c.f, cx=12.25, cy=-7.5, k1=c.k1, k2=c.k2)
            for g, c in b.cameras.items()
        }
    )
    write_bal(shifted, tmp_path / "s.txt")
    back = read_bal(tmp_path / "s.txt", image_size=(4000, 3000))
    np.testing.assert_allclose(
        reprojection_residuals(back), reprojection_residuals(shifted), atol=1e-9
    )


def test_default_image_size_holds_every_observation():
    b = read_bal(DUBROVNIK)
    w, h = b.image_sizes()[0]
    uv = b.observations.uv
    assert np.all(uv >= -0.5) and np.all(uv[:, 0] <= w - 0.5) and np.all(uv[:, 1] <= h - 0.5)


# --- errors --------------------------------------------------------------------------------


def _write(tmp_path, text, name="bad.txt"):
    p = tmp_path / name
    p.write_text(text)
    return p


GOOD = "1 2 2\n0 0 1.0 2.0\n0 1 -3.0 4.0\n0 0 0\n0 0 0\n1000\n0\n0\n0 0 -10\n1 1 -10\n"


def test_good_minimal_file(tmp_path):
    b = read_bal(_write(tmp_path, GOOD))
    assert (b.n_images, b.n_points, b.n_observations) == (1, 2, 2)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (GOOD.replace("-3.0", "x3"), r"line 3: 'x3' is not a number"),
        (GOOD.replace("1000", "1,000"), r"line 6: '1,000' is not a number"),
        (GOOD.rsplit("\n", 2)[0] + "\n", r"truncated.*ends in the point coordinates"),
        ("1 2 2\n0 0 1.0 2.0\n", r"truncated.*ends in the observations"),
        (GOOD + "7\n", r"line 11: counts do not match.*first extra value '7'"),
        (
            GOOD.replace("0 1 -3.0", "0 5 -3.0"),
            r"line 3: observation 1 refers to camera 0 and point 5",
        ),
        (GOOD.replace("0 1 -3.0", "0.5 1 -3.0"), r"line 3: observation 1"),
        (GOOD.replace("1000", "-1000"), r"line 6: camera 0 has focal length -1000"),
        (GOOD.replace("1 1 -10", "1 nan -10"), r"line 10: point 1 holds NaN"),
        ("1 2\n", r"truncated: the header needs 3 numbers"),
        ("1.5 2 2\n", r"line 1: the header must be three non-negative integers"),
        ("", r"truncated"),
        ("0 0 0\n", r"line 1: the header announces no cameras"),
    ],
)
def test_named_errors(tmp_path, text, match):
    with pytest.raises(FileFormatError, match=match):
        read_bal(_write(tmp_path, text))


def test_a_repeated_observation_is_refused_naming_both_lines(tmp_path):
    # a camera's second observation of one point: read before without a word, a block that
    # the CSV and Bundler readers refuse when written as theirs, and the adjustment refused
    # naming neither file nor line; the Bundler reader refuses the same repeat by its line
    lines = DUBROVNIK.read_text().splitlines()
    m, p, n = map(int, lines[0].split())
    at = next(k for k, ln in enumerate(lines) if k and ln.split())  # the first observation
    dup = [f"{m} {p} {n + 1}", *lines[1 : at + 2], lines[at + 1], *lines[at + 2 :]]
    path = tmp_path / "dup.bal"
    path.write_text("\n".join(dup) + "\n")
    cam, pt = lines[at + 1].split()[:2]
    want = (
        rf"dup.bal, line {at + 3}: observation 2 is camera {cam}'s observation of point {pt} "
        rf"again \(observation 1, line {at + 2}\); a camera observes a point once: remove one"
    )
    with pytest.raises(FileFormatError, match=want):
        read_bal(path)
    block = read_bal(DUBROVNIK)
    pg.bundle.write_bundler(block, tmp_path / "b.out", drop_extras=True)
    out = (tmp_path / "b.out").read_text().splitlines()
    k = 2 + 5 * block.n_images + 2  # the first point's view list
    views = out[k].split()
    out[k] = " ".join([str(int(views[0]) + 1), *views[1:], *views[1:5]])
    (tmp_path / "b.out").write_text("\n".join(out) + "\n")
    with pytest.raises(FileFormatError, match=r"point 0 has two views of camera"):
        pg.bundle.read_bundler(tmp_path / "b.out", image_size=(2000, 2000))


def test_an_observation_beyond_any_image_is_named_with_its_line(tmp_path):
    # BAL has no image size: it is the smallest even size holding every observation, so one
    # stray observation 600 000 px out made an image of 1 200 000 px, refused as "width must
    # be a whole number of pixels from 1 to 1000000 ... (image_size=(1200000, 8))", an
    # image_size never given; the observation is named with its line and the routes
    text = GOOD.replace("0 1 -3.0 4.0", "0 1 -6e5 4.0")
    with pytest.raises(FileFormatError, match=r"bad.txt, line 3: observation 1 lies at "
                       r"\(-600000, 4\) px from the image centre.*1200000 x 8 px is more "
                       r"than the 1000000 px of an image side: remove that observation.*"
                       r"give the images' size \(image_size=\(width, height\)\)"):  # fmt: skip
        read_bal(_write(tmp_path, text))
    with pytest.warns(ImageSizeWarning):  # the route: the size given, a warning
        b = read_bal(_write(tmp_path, text), image_size=(4000, 3000))
    assert b.n_observations == 2
    # the largest side read from the observations is still taken
    edge = GOOD.replace("0 1 -3.0 4.0", "0 1 -5e5 4.0")
    assert read_bal(_write(tmp_path, edge)).image_sizes()[0].tolist() == [1000000, 8]


def test_missing_and_damaged_files(tmp_path):
    with pytest.raises(FileFormatError, match="no such file"):
        read_bal(tmp_path / "nope.txt")
    p = tmp_path / "cut.bz2"
    p.write_bytes(bz2.compress(GOOD.encode())[:-10])
    with pytest.raises(FileFormatError, match="bzip2"):
        read_bal(p)


def test_writer_refuses_what_bal_cannot_hold(tmp_path):
    b = read_bal(DUBROVNIK)
    c = b.cameras[1]
    bad = b.with_calibrations({1: MetashapeCalibration(c.width, c.height, c.f, p1=1e-4)})
    with pytest.raises(InputError, match=r"image 1 .*p1 = 0.0001.*only f, k1, k2"):
        write_bal(bad, tmp_path / "x.txt")
    ctrl = b.replace(role=np.array(["tie"] * 6 + ["control"]), point_sigma=np.full((7, 3), 0.01))
    with pytest.raises(InputError, match=r"1 control point.*drop_extras=True"):
        write_bal(ctrl, tmp_path / "x.txt")
    assert not (tmp_path / "x.txt").exists()
    write_bal(ctrl, tmp_path / "x.txt", drop_extras=True)
    assert read_bal(tmp_path / "x.txt").n_points == 7
    uneven = b.with_observations(sigma=np.linspace(0.5, 1.0, 19))
    with pytest.raises(InputError, match="standard deviations"):
        write_bal(uneven, tmp_path / "y.txt")


def test_write_is_atomic(tmp_path, monkeypatch):
    b = read_bal(DUBROVNIK)
    out = tmp_path / "keep.txt"
    out.write_text("old")

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        write_bal(b, out)
    assert out.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]


@pytest.mark.parametrize("eps", [1e-3, 1e-6, 1e-9, 1e-12, 0.0])
def test_rotations_near_gimbal_lock_survive_the_angles(tmp_path, eps):
    """Cameras at phi = 90 deg - eps: the block's M = M(omega, phi, kappa) equals BAL's R to
    rounding (the angles are chosen so that omega and kappa compensate each other)."""
    rng = np.random.default_rng(11)
    R = []
    for sign in (1.0, -1.0):
        for _ in range(20):
            om, ka = rng.uniform(-3, 3, 2)
            R.append(pg.opk_matrix(om, sign * (math.pi / 2 - eps), ka))
    R = Rotation.from_matrix(np.array(R)).as_matrix()  # re-orthonormalised by scipy
    m = len(R)
    cams = np.column_stack(
        [
            Rotation.from_matrix(R).as_rotvec(),
            rng.normal(0, 5, (m, 3)),
            np.full(m, 1000.0),
            np.zeros((m, 2)),
        ]
    )
    lines = [f"{m} 1 {m}"] + [f"{i} 0 1.5 -2.5" for i in range(m)]
    lines += [repr(v) for v in cams.ravel().tolist()] + ["1.0", "2.0", "3.0"]
    path = tmp_path / "lock.txt"
    path.write_text("\n".join(lines) + "\n")
    b = read_bal(path)
    np.testing.assert_allclose(
        b.rotations(), Rotation.from_rotvec(cams[:, :3]).as_matrix(), rtol=0, atol=2e-15
    )
    write_bal(b, tmp_path / "again.txt")
    again = read_bal(tmp_path / "again.txt")
    np.testing.assert_allclose(again.rotations(), b.rotations(), rtol=0, atol=2e-15)
