"""Bundler files (bundle.out v0.3): the manual's projection against photogeom's, a hand-made
file, round trips, refusals, image sizes from image files, the command line and pycolmap."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import photogeom as pg
from photogeom.bundle import projected_pixels, read_bundler, write_bundler
from photogeom.errors import FileFormatError, InputError


def _manual_xy(R, t, f, k1, k2, X):
    """Bundler's projection as its manual writes it: P = R X + t, p = -P / P.z,
    p' = f (1 + k1 |p|^2 + k2 |p|^4) p (pixels from the image centre, y up)."""
    P = X @ R.T + t
    p = -P[:, :2] / P[:, 2:3]
    r2 = np.sum(p * p, axis=1, keepdims=True)
    return f * (1 + k1 * r2 + k2 * r2 * r2) * p


def scene(seed: int, m: int = 4, p: int = 25, zero=(), noise: float = 0.0):
    """A Bundler file of random cameras about 20 m above random points (camera indices in
    ``zero`` not oriented), with the manual's projections (plus ``noise`` px) as views.

    Returns the text and the truth: ``{camera: (R, t, f, k1, k2)}``, points (p, 3),
    views (camera, point, x, y)."""
    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.uniform(-6, 6, (p, 2)), rng.uniform(-1, 1, p)])
    lines = ["# Bundle file v0.3", f"{m} {p}"]
    cams = {}
    for k in range(m):
        if k in zero:
            lines += ["0 0 0"] * 5
            continue
        C = np.array([rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(18, 22)])
        R = Rotation.from_euler("xyz", rng.normal(0, 0.1, 3)).as_matrix()
        t = -R @ C
        f, k1, k2 = rng.uniform(500, 900), rng.normal(0, 0.05), rng.normal(0, 0.01)
        cams[k] = (R, t, f, k1, k2)
        lines.append(f"{f!r} {k1!r} {k2!r}")
        lines += [" ".join(map(repr, r)) for r in R.tolist()]
        lines.append(" ".join(map(repr, t.tolist())))
    xy = {k: _manual_xy(*c, X) + rng.normal(0, noise, (p, 2)) for k, c in cams.items()}
    views = []
    for j in range(p):
        lines.append(" ".join(map(repr, X[j].tolist())))
        lines.append("255 128 0")
        v = [(k, j, *xy[k][j].tolist()) for k in cams]
        views += v
        lines.append(f"{len(v)} " + " ".join(f"{k} {j} {a!r} {b!r}" for k, j, a, b in v))
    return "\n".join(lines) + "\n", cams, X, np.array(views)


SIZES = {0: (640, 480), 1: (641, 479), 2: (800, 600), 3: (1000, 750), 4: (640, 480)}


def test_projection_agrees_with_the_manual_to_1e_9_px(tmp_path):
    text, cams, X, _ = scene(3, m=5, zero=(2,))
    path = tmp_path / "bundle.out"
    path.write_text(text)
    b = read_bundler(path, image_size={k: SIZES[k] for k in cams})
    assert b.image_ids.tolist() == [0, 1, 3, 4]  # camera 2 (all zeros) left out
    assert b.n_observations == 4 * 25
    uv, _ = projected_pixels(b)
    # the manual's projection, moved to photogeom's pixels: Bundler's corners are at
    # (+-w/2, +-h/2), photogeom's origin is the first pixel's centre, v down
    row = {k: i for i, k in enumerate(b.image_ids.tolist())}
    cam = b.observations.image_ids
    want = np.empty_like(uv)
    for k, (R, t, f, k1, k2) in cams.items():
        sel = cam == k
        xy = _manual_xy(R, t, f, k1, k2, X[b.obs_point[sel]])
        w, h = SIZES[k]
        want[sel] = np.column_stack([xy[:, 0] + w / 2 - 0.5, h / 2 - 0.5 - xy[:, 1]])
        np.testing.assert_allclose(b.exterior[row[k], :3], -R.T @ t, atol=1e-12)
    np.testing.assert_allclose(uv, want, atol=1e-9, rtol=0)
    np.testing.assert_allclose(b.observations.uv, want, atol=1e-9, rtol=0)


def test_a_hand_written_file(tmp_path):
    # camera 0: f 1000, R = I, t = (0, 0, -10): centre (0, 0, 10), looking down;
    # camera 1 not oriented; camera 2: k1 = 0.1 (|p|^2 = 0.05: 1.005 times the pinhole)
    (tmp_path / "bundle.out").write_text(
        "# Bundle file v0.3\n3 2\n"
        "1000 0 0\n1 0 0\n0 1 0\n0 0 1\n0 0 -10\n"
        "0 0 0\n0 0 0\n0 0 0\n0 0 0\n0 0 0\n"
        "1000 0.1 0\n1 0 0\n0 1 0\n0 0 1\n0 0 -10\n"
        "1 2 0\n255 255 255\n2 0 7 100 200 2 3 100.5 201\n"
        "0 0 5\n0 0 0\n1 0 8 0 0\n"
    )
    (tmp_path / "list.txt").write_text("a.jpg 0 1000\nb.jpg\nc.jpg 0 1000.0\n")
    b = read_bundler(tmp_path / "bundle.out", image_size=(2000, 1000))
    assert b.image_ids.tolist() == ["a.jpg", "c.jpg"]
    assert b.camera_ids.tolist() == [0, 2]
    np.testing.assert_allclose(b.exterior[:, :3], [[0, 0, 10], [0, 0, 10]])
    np.testing.assert_allclose(b.exterior[:, 3:], 0, atol=1e-15)
    c = b.cameras[2]
    assert (c.width, c.height, c.f, c.k1, c.k2, c.cx, c.cy) == (2000, 1000, 1000, 0.1, 0, 0, 0)
    # u = x + (2000 - 1) / 2, v = (1000 - 1) / 2 - y
    np.testing.assert_array_equal(
        b.observations.uv, [[1099.5, 299.5], [1100.0, 298.5], [999.5, 499.5]]
    )
    np.testing.assert_allclose(projected_pixels(b)[0], b.observations.uv, atol=1e-9)
    assert b.free[0] == b.free[2] and set(b.free[0]) == {"f", "k1", "k2"}


def _same(a, b, tol=1e-12):
    np.testing.assert_array_equal(a.point_ids, b.point_ids)
    np.testing.assert_array_equal(a.obs_point, b.obs_point)
    np.testing.assert_allclose(a.xyz, b.xyz, rtol=tol, atol=0)
    np.testing.assert_allclose(a.exterior[:, :3], b.exterior[:, :3], rtol=tol, atol=tol)
    np.testing.assert_allclose(a.rotations(), b.rotations(), atol=tol)
    np.testing.assert_allclose(a.observations.uv, b.observations.uv, atol=1e-9)
    np.testing.assert_allclose(a.calibration_matrix(), b.calibration_matrix(), atol=tol)


@settings(
    max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(seed=st.integers(0, 2**31), m=st.integers(1, 5), p=st.integers(0, 12))
def test_round_trip(tmp_path, seed, m, p):
    text, _, _, _ = scene(seed, m=m, p=p, zero=(1,) if m > 2 else (), noise=0.5)
    src = tmp_path / f"s{seed}.out"
    src.write_text(text)
    a = read_bundler(src, image_size=(640, 480))
    out = tmp_path / f"w{seed}.out"
    write_bundler(a, out)
    b = read_bundler(out, image_size=(640, 480))
    assert b.image_ids.tolist() == [str(i) for i in a.image_ids.tolist()]  # from the list
    _same(a, b)
    write_bundler(b, out)
    assert read_bundler(out, image_size=(640, 480)).n_observations == a.n_observations


def test_group_cameras_joins_equal_intrinsics(tmp_path):
    text, *_ = scene(5, m=3)
    lines = text.splitlines()
    lines[7] = lines[2]  # camera 1 gets camera 0's f, k1, k2
    (tmp_path / "b.out").write_text("\n".join(lines) + "\n")
    sizes = {0: (640, 480), 1: (640, 480), 2: (640, 480)}
    assert read_bundler(tmp_path / "b.out", image_size=sizes).camera_ids.tolist() == [0, 1, 2]
    g = read_bundler(tmp_path / "b.out", image_size=sizes, group_cameras=True)
    assert g.camera_ids.tolist() == [0, 2]
    assert g.image_camera.tolist() == [0, 0, 1]
    other = {**sizes, 1: (800, 600)}  # another size: another camera
    assert (
        read_bundler(tmp_path / "b.out", image_size=other, group_cameras=True).camera_ids.size == 3
    )


def test_image_sizes_from_the_image_files(tmp_path):
    from PIL import Image

    text, *_ = scene(6, m=2, p=5)
    (tmp_path / "bundle.out").write_text(text)
    (tmp_path / "bundle.out.list.txt").write_text("img/a.png\nimg/b.jpg\n")
    (tmp_path / "img").mkdir()
    Image.new("RGB", (64, 48)).save(tmp_path / "img" / "a.png")
    Image.new("RGB", (50, 40)).save(tmp_path / "img" / "b.jpg")
    b = read_bundler(tmp_path / "bundle.out")
    assert b.image_ids.tolist() == ["img/a.png", "img/b.jpg"]
    assert b.image_sizes().tolist() == [[64, 48], [50, 40]]
    (tmp_path / "img" / "b.jpg").unlink()
    with pytest.raises(InputError, match=r"img/b.jpg.*image_size"):
        read_bundler(tmp_path / "bundle.out")
    (tmp_path / "bundle.out.list.txt").unlink()
    with pytest.raises(InputError, match=r"no image size.*image_size"):
        read_bundler(tmp_path / "bundle.out")


GOOD = (
    "# Bundle file v0.3\n2 1\n"
    "1000 0 0\n1 0 0\n0 1 0\n0 0 1\n0 0 -10\n"
    "0 0 0\n0 0 0\n0 0 0\n0 0 0\n0 0 0\n"
    "1 2 0\n255 255 255\n1 0 7 100 200\n"
)


@pytest.mark.parametrize(
    "edit, match",
    [
        (lambda s: s.replace("2 1\n", "2 2\n"), r"truncated.*2 points.*point 1"),
        (lambda s: s.replace("2 1\n", "3 1\n"), r"truncated.*3 cameras.*ends in camera 2"),
        (lambda s: s + "1 2 3\n", r"line 16: counts do not match"),
        (lambda s: s.replace("1 0 7 100 200", "1 1 7 100 200"), r"line 15: .*camera 1 is not orie"),
        (lambda s: s.replace("1 0 7 100 200", "1 2 7 100 200"), r"line 15: .*cameras are 0..1"),
        (
            lambda s: s.replace("1 0 7 100 200", "2 0 7 100 200"),
            r"line 15: point 0: .*view list.*5 numbers for 2 views",
        ),
        (
            lambda s: s.replace("0 1 0\n0 0 1\n0 0 -10", "0 2 0\n0 0 1\n0 0 -10"),
            "line 4: .*not a rot",
        ),
        (lambda s: s.replace("1000 0 0", "-1000 0 0"), "line 3: camera 0 has focal length -1000"),
        (lambda s: s.replace("v0.3", "v0.5"), "line 1: .*only version v0.3"),
        (lambda s: s.replace("1 2 0\n", "1 nan 0\n"), "line 13: point 0 holds NaN"),
        (lambda s: s.replace("1 2 0\n", "1 x 0\n"), "line 13: 'x' is not a number"),
        (lambda s: s[:40], "truncated.*ends in camera 0"),
        (lambda s: s.replace("1 0 7 100 200", "2 0 7 100 200 0 8 1 2"), r"line 15: .*two views of"),
        (lambda s: s.replace("1000 0 0\n1 0 0\n0 1 0\n0 0 1\n0 0 -10", "\n".join(["0 0 0"] * 5))
         .replace("1 0 7 100 200", "0"), "none of its 2 cameras is oriented"),
    ],
)
def test_refusals_name_the_line(tmp_path, edit, match):
    (tmp_path / "b.out").write_text(edit(GOOD))
    with pytest.raises(FileFormatError, match=match):
        read_bundler(tmp_path / "b.out", image_size=(640, 480))


def test_an_image_list_of_another_length_is_refused(tmp_path):
    (tmp_path / "b.out").write_text(GOOD)
    (tmp_path / "list.txt").write_text("a.jpg\n")
    with pytest.raises(FileFormatError, match=r"names 1 image.*2 cameras"):
        read_bundler(tmp_path / "b.out", image_size=(640, 480))


def test_writer_refuses_what_bundler_cannot_hold(tmp_path):
    (tmp_path / "b.out").write_text(GOOD)
    b = read_bundler(tmp_path / "b.out", image_size=(640, 480))
    cal = b.cameras[0]
    from dataclasses import replace

    off = b.with_calibrations({0: replace(cal, cx=3.0, cy=-2.0)})
    with pytest.raises(InputError, match=r"cx = 3.0, cy = -2.0 px.*drop_extras=True"):
        write_bundler(off, tmp_path / "o.out")
    assert not (tmp_path / "o.out").exists()
    write_bundler(off, tmp_path / "o.out", drop_extras=True)
    back = read_bundler(tmp_path / "o.out", image_size=(640, 480))
    # from the principal point: the projections are those of the block written
    np.testing.assert_allclose(
        back.observations.uv - projected_pixels(back)[0],
        off.observations.uv - projected_pixels(off)[0],
        atol=1e-9,
    )
    with pytest.raises(InputError, match=r"p1 = 0.001.*only f, k1, k2"):
        write_bundler(b.with_calibrations({0: replace(cal, p1=1e-3)}), tmp_path / "p.out",
                      drop_extras=True)  # fmt: skip
    two = b.with_observations(sigma=np.array([1.0]))
    write_bundler(two, tmp_path / "s.out")  # one sigma: fine


def test_detect_and_dispatch(tmp_path):
    (tmp_path / "b.out").write_text(GOOD)
    assert pg.bundle.detect_format(tmp_path / "b.out") == "bundler"
    b = pg.bundle.read_block(tmp_path / "b.out", image_size=(640, 480))
    pg.bundle.write_block(b, tmp_path / "c.out")
    assert pg.bundle.detect_format(tmp_path / "c.out") == "bundler"
    assert (tmp_path / "c.out.list.txt").read_text() == "0\n"
    from photogeom.bundle.io_formats import check_block_target
    from photogeom.errors import OutputError

    with pytest.raises(OutputError, match=r"a Bundler block is one file: give a file name \(\.out"):
        check_block_target(tmp_path, "bundler")


def test_cli_adjust_a_bundler_file(cli, tmp_path):
    text, *_ = scene(11, m=5, p=60, zero=(3,), noise=0.3)
    (tmp_path / "bundle.out").write_text(text)
    (tmp_path / "list.txt").write_text("".join(f"IMG_{k}.JPG 0 700\n" for k in range(5)))
    code, out, err = cli(
        "bundle", "adjust", tmp_path / "bundle.out", "--image-size", "1000x750", "--json",
        "--free", "none", "--datum", "free", "-o", tmp_path / "adj.out",
    )  # fmt: skip
    assert code == 0, err
    d = json.loads(out)
    assert d["input"]["format"] == "bundler"
    assert len(d["images"]) == 4
    assert 0.15 < d["sigma0"] < 0.6  # noise 0.3 px, sigma 1 px
    assert (tmp_path / "adj.out.list.txt").read_text().splitlines() == [
        "IMG_0.JPG", "IMG_1.JPG", "IMG_2.JPG", "IMG_4.JPG"
    ]  # fmt: skip
    code, _, err = cli("bundle", "adjust", tmp_path / "bundle.out")
    assert code != 0 and "--image-size" in err


def test_cli_convert_to_colmap_agrees_with_pycolmap(cli, tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    text, cams, X, _ = scene(12, m=4, p=20, zero=(1,))
    (tmp_path / "bundle.out").write_text(text)
    (tmp_path / "list.txt").write_text("a.jpg\nb.jpg\nc.jpg\nd.jpg\n")
    code, _, err = cli(
        "bundle", "convert", tmp_path / "bundle.out", tmp_path / "model", "--to", "colmap",
        "--image-size", "800x600",
    )  # fmt: skip
    assert code == 0, err
    rec = pycolmap.Reconstruction(str(tmp_path / "model"))
    names = {0: "a.jpg", 2: "c.jpg", 3: "d.jpg"}
    by = {im.name: im for im in rec.images.values()}
    assert sorted(by) == sorted(names.values())
    for k, (R, t, f, k1, k2) in cams.items():
        im = by[names[k]]
        cam = rec.cameras[im.camera_id]
        # pycolmap's projection of the points against the manual's, in COLMAP's pixels
        # (corner origin, y down): u = x + w / 2, v = h / 2 - y
        xy = _manual_xy(R, t, f, k1, k2, X)
        want = np.column_stack([xy[:, 0] + 400, 300 - xy[:, 1]])
        got = np.array([cam.img_from_cam(im.cam_from_world() * x) for x in X])
        np.testing.assert_allclose(got, want, atol=1e-6)
        np.testing.assert_allclose(im.projection_center(), -R.T @ t, atol=1e-9)
        # its 2D points: the views, in the same pixels
        stored = np.array([q.xy for q in im.points2D])
        assert len(stored) == len(X)
        pts = {pid: pt.xyz for pid, pt in rec.points3D.items()}
        seen = np.array([pts[q.point3D_id] for q in im.points2D])
        xy = _manual_xy(R, t, f, k1, k2, seen)
        np.testing.assert_allclose(stored, np.column_stack([xy[:, 0] + 400, 300 - xy[:, 1]]),
                                   atol=1e-6)  # fmt: skip


def test_grid_fit_of_a_bundler_file(cli, tmp_path):
    # an adjusted block as Metashape exports it: tie points with their residuals (noise)
    text, *_ = scene(14, m=4, p=300, noise=0.3)
    out, npz = tmp_path / "block.out", tmp_path / "g.npz"
    out.write_text(text)
    code, _, err = cli("grid", "fit", out, "--spacing", "250", "-o", npz, "--folds", "0")
    assert code != 0 and "Bundler file holds no image size" in err, err
    assert "--image-size WIDTHxHEIGHT" in err
    code, _, err = cli(
        "grid", "fit", out, "--spacing", "250", "-o", npz, "--folds", "0",
        "--image-size", "1000x750",
    )  # fmt: skip
    assert code == 0, err
    grids = pg.calibration.load_grids(npz)
    block = pg.bundle.read_block(out, image_size=(1000, 750))
    want = pg.calibration.fit_residual_grids(block, 250, folds=0)
    assert sorted(grids) == sorted(want) == [0, 1, 2, 3]
    for k, g in want.items():
        assert grids[k].image_size == (1000, 750)
        np.testing.assert_allclose(grids[k].nodes, g.nodes, rtol=0, atol=1e-12)


def test_a_bundler_pipe_read_as_bal_names_the_format(cli, tmp_path):
    # a pipe's content is not looked at before it is read: its format must be given
    text, *_ = scene(13, m=3, p=900)  # more than the 64 KiB read before the rest
    assert len(text) > 70_000
    for body in (GOOD, text):
        (tmp_path / "b.txt").write_text(body)
        with pytest.raises(FileFormatError, match=r"line 1: a Bundler file, not a BAL file"):
            pg.bundle.read_bal(tmp_path / "b.txt")
    code, _, err = cli("bundle", "adjust", tmp_path / "b.txt", "--format", "bal")
    assert code != 0 and "give --format bundler" in err


@pytest.mark.parametrize("counts", ["2 -5", "-1 3", "2 1.5", "2", "2 1 0"])
def test_a_bad_header_of_a_long_file_is_named(tmp_path, counts):
    # a file over the 64 KiB looked at first: its header bounds the size read
    (tmp_path / "n.out").write_text(f"# Bundle file v0.3\n{counts}\n" + "1 2 3\n" * 30000)
    with pytest.raises(FileFormatError, match=r"line 2: the header must be two non-negative"):
        read_bundler(tmp_path / "n.out", image_size=(10, 10))
    (tmp_path / "n.out").write_text(f"# Bundle file v0.3\n{counts}\n" + "1 2 3\n")
    with pytest.raises(FileFormatError, match=r"the header must be two non-negative"):
        read_bundler(tmp_path / "n.out", image_size=(10, 10))


def test_grid_evaluate_of_a_bundler_file_without_its_images_names_image_size(cli, tmp_path):
    text, *_ = scene(15, m=3, p=40, noise=0.3)
    (tmp_path / "block.out").write_text(text)
    code, _, err = cli("grid", "evaluate", tmp_path / "block.out", "--spacing", "250")
    assert code != 0
    assert "a Bundler file holds no image size" in err and "image_size=" not in err
    assert "give their size with --image-size WIDTHxHEIGHT" in err
    # the option named (before: grid evaluate had none, and a conversion was the route)
    code, out, err = cli(
        "grid", "evaluate", tmp_path / "block.out", "--spacing", "250", "--json",
        "--image-size", "1000x750",
    )  # fmt: skip
    assert code == 0, err
    # with its images beside the list (Metashape's export folder), their sizes are read
    from PIL import Image

    names = [f"IMG_{k}.png" for k in range(3)]
    (tmp_path / "list.txt").write_text("\n".join(names) + "\n")
    for n in names:
        Image.new("L", (1000, 750)).save(tmp_path / n)
    code, out, err = cli(
        "grid", "evaluate", tmp_path / "block.out", "--spacing", "250", "--json"
    )  # fmt: skip
    assert code == 0, err
    assert set(names) <= set(out.replace('"', " ").split())


@pytest.mark.parametrize(
    ("command", "says"),
    [
        (("bundle", "adjust"), ["a BAL or Bundler file", "a file for BAL and Bundler"]),
        (("grid", "fit"), ["a Bundler file (default: read from the images its list names)"]),
        (("grid", "evaluate"), ["BAL file or Bundler file"]),
        (("grid", "sweep"), ["BAL file or Bundler file"]),
        (("grid", "report"), ["BAL file or Bundler file"]),
    ],
)
def test_the_help_of_every_block_reader_names_bundler_files(cli, command, says):
    # the commands read Bundler files, but their --help named CSV, COLMAP and BAL only
    # (SOURCE and -o of bundle adjust, --image-size of grid fit, BLOCK of the grid commands)
    code, out, _ = cli(*command, "--help")
    assert code == 0
    text = " ".join(out.split())
    for s in says:
        assert s in text


def test_the_readers_share_one_rotation_check():
    # Bundler's camera rotations and Metashape's transforms are checked by one function,
    # which agrees with the package's orthogonality defect and determinant
    from photogeom.bundle import _textio, io_bundler, io_metashape

    rng = np.random.default_rng(4)
    R = Rotation.random(6, random_state=rng).as_matrix()
    R[1] *= -1  # a reflection
    R[2] *= 1.001  # a scale
    R[3, 0, 1] += 2e-6  # off by more than Metashape's 1e-6, less than Bundler's 1e-5
    bad, defect, det = _textio.rotation_defects(R, 1e-6)
    assert bad.tolist() == [False, True, True, True, False, False]
    np.testing.assert_allclose(det, np.linalg.det(R))
    assert np.all(defect <= pg.orthogonality_defect(R) + 1e-15)  # max |.| <= Frobenius
    assert _textio.rotation_defects(R, 1e-5)[0].tolist() == [False, True, True, False, False, False]
    assert not hasattr(io_metashape, "_check_rotation")  # no copy of its own
    assert io_bundler.rotation_defects is _textio.rotation_defects
