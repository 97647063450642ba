"""Camera poses of a Metashape camera export (cameras.xml) as start values of a block.

The export is written here from the documented format (camera transforms camera -> component
frame with computer-vision axes, component and chunk transforms as rotation, translation,
scale, cameras inside <group>s, unaligned and disabled cameras), from poses known in the
world frame: read back, they are those poses; the start block projects its tie points as
OpenCV's projectPoints does with the poses composed from the file's matrices here; a block of
tie points (a COLMAP model in another frame) started from it and adjusted gives the truth.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from photogeom.bundle import bundle_adjust, projected_pixels, write_colmap
from photogeom.bundle.io_metashape import (
    match_labels,
    read_metashape_cameras,
    start_from_metashape,
)
from photogeom.errors import FileFormatError, InputError
from photogeom.simulate import uav_block

FLIP = np.diag([1.0, -1.0, -1.0])
WGS84 = (
    'GEOGCS["WGS 84",DATUM["World Geodetic System 1984",SPHEROID["WGS 84",6378137,'
    '298.257223563,AUTHORITY["EPSG","7030"]],AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,'
    'AUTHORITY["EPSG","8901"]],UNIT["degree",0.01745329251994328,AUTHORITY["EPSG","9102"]],'
    'AUTHORITY["EPSG","4326"]]'
)
LOCAL = 'LOCAL_CS["Local Coordinates (m)",LOCAL_DATUM["Local Datum",0],UNIT["metre",1]]'


def _rot(a, b, c):
    """A rotation matrix from three angles (rad), composed about x, y, z."""
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    Rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    Ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    Rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _opk(omega, phi, kappa):
    """photogeom's M = M3(kappa) M2(phi) M1(omega) (spec 01), written out here."""
    co, so, cp, sp, ck, sk = (np.cos(omega), np.sin(omega), np.cos(phi), np.sin(phi),
                              np.cos(kappa), np.sin(kappa))  # fmt: skip
    M1 = np.array([[1, 0, 0], [0, co, so], [0, -so, co]])
    M2 = np.array([[cp, 0, -sp], [0, 1, 0], [sp, 0, cp]])
    M3 = np.array([[ck, sk, 0], [-sk, ck, 0], [0, 0, 1]])
    return M3 @ M2 @ M1


def _sim(s, R, t):
    A = np.eye(4)
    A[:3, :3] = s * R
    A[:3, 3] = t
    return A


def _tf_xml(s, R, t) -> str:
    return (
        f"<transform><rotation locked=\"false\">{' '.join(map(repr, R.ravel().tolist()))}"
        f"</rotation><translation>{' '.join(map(repr, t.tolist()))}</translation>"
        f"<scale>{s!r}</scale></transform>"
    )


def _calibration_xml(c) -> str:
    terms = "".join(
        f"<{n}>{getattr(c, n)!r}</{n}>"
        for n in ("f", "cx", "cy", "b1", "b2", "k1", "k2", "k3", "k4", "p1", "p2")
    )
    return (
        f'<calibration type="frame" class="adjusted"><resolution width="{c.width}" '
        f'height="{c.height}"/>{terms}</calibration>'
    )


def export_xml(labels, exterior, cal, *, chunk=None, component=None, reference=WGS84,
               unaligned=(), disabled=(), orientation=None, sensor_type="frame",
               fixed=False) -> tuple[str, list[np.ndarray]]:  # fmt: skip
    """A camera export of cameras at ``exterior`` (world frame: X0, omega, phi, kappa) with
    one sensor; the chunk's and the component's transforms ``(s, R, t)`` (None: none). The
    first half of the cameras in a <group>. Returns the text and each camera's 4 x 4
    camera -> world matrix as composed from the file's matrices."""
    C = _sim(*chunk) if chunk is not None else np.eye(4)
    K = _sim(*component) if component is not None else np.eye(4)
    to_comp = np.linalg.inv(C @ K)
    cams, world = [], []
    for k, (lab, e) in enumerate(zip(labels, exterior)):
        Rw = (FLIP @ _opk(*e[3:])).T  # camera (x right, y down, z forward) -> world
        T = to_comp @ _sim(1.0, Rw, e[:3])  # camera -> component
        T[:3, :3] /= np.cbrt(np.linalg.det(T[:3, :3]))  # the rotation alone (exact scale 1)
        T[3] = [0, 0, 0, 1]
        world.append(C @ K @ T)
        attrs = f'id="{k}" sensor_id="0" component_id="0" label="{lab}"'
        if lab in disabled:
            attrs += ' enabled="false"'
        body = "" if lab in unaligned else (
            f"<transform>{' '.join(map(repr, T.ravel().tolist()))}</transform>"
        )  # fmt: skip
        if orientation and lab in orientation:
            body += f"<orientation>{orientation[lab]}</orientation>"
        cams.append(f"<camera {attrs}>{body}</camera>")
    half = len(cams) // 2
    cameras = '<group id="0" label="Folder 1" type="folder">' + "".join(cams[:half])
    cameras += "</group>" + "".join(cams[half:])
    comp = _tf_xml(*component) if component is not None else ""
    prop = '<property name="fixed" value="true"/>' if fixed else ""
    text = f"""<?xml version="1.0" encoding="UTF-8"?>
<document version="2.0.0"><chunk label="Chunk 1" enabled="true">
<sensors next_id="1"><sensor id="0" label="FC300S (3.61mm)" type="{sensor_type}">
<resolution width="{cal.width}" height="{cal.height}"/>{prop}
<bands><band label="Red"/><band label="Green"/><band label="Blue"/></bands>
{_calibration_xml(cal)}</sensor></sensors>
<components next_id="1" active_id="0"><component id="0" label="Component 1">{comp}
<region><center>0 0 0</center><size>1 1 1</size><R>1 0 0 0 1 0 0 0 1</R></region>
</component></components>
<cameras next_id="{len(cams)}" next_group_id="1">{cameras}</cameras>
{_tf_xml(*chunk) if chunk is not None else ""}
<reference>{reference}</reference>
<region><center>0 0 0</center><size>1 1 1</size><R>1 0 0 0 1 0 0 0 1</R></region>
</chunk></document>
"""
    return text, world


ECEF = np.array([4_190_000.0, 171_000.0, 4_780_000.0])
CHUNK = (37.25, _rot(0.3, -1.1, 2.0), ECEF)
COMPONENT = (0.8, _rot(-0.2, 0.4, 0.1), np.array([1.5, -2.0, 0.25]))


@pytest.fixture(scope="module")
def sim():
    s = uav_block(
        "FC300S", seed=3, strips=2, images_per_strip=4, gcps=None, checks=0,
        gnss_sigma=None, imu_sigma_deg=None, tie_points_per_image=40,
    )  # fmt: skip
    cal = replace(s.truth.calibrations[0], b2=0.0)  # OpenCV and COLMAP have no B2
    truth = s.truth.with_calibrations({s.truth.camera_ids[0].item(): cal})
    return truth.with_observations(uv=projected_pixels(truth)[0]), cal  # without noise


def _labels(block):
    """Metashape's labels of the block's images (their ids, 0, 1, ...)."""
    return [str(i) for i in block.image_ids.tolist()]


def _world(block, offset):
    e = block.exterior.copy()
    e[:, :3] += offset
    return e


def test_round_trip_geocentric(tmp_path, sim):
    truth, cal = sim
    ext = _world(truth, ECEF)
    text, _ = export_xml(_labels(truth), ext, cal, chunk=CHUNK, component=COMPONENT)
    (tmp_path / "cameras.xml").write_text(text)
    p = read_metashape_cameras(tmp_path / "cameras.xml")
    assert p.labels.tolist() == _labels(truth)
    assert p.frame == "geocentric" and p.crs == "EPSG:4978"
    assert np.all(p.aligned) and np.all(p.enabled) and np.all(p.orientation == 1)
    # positions of 6e6 m: a few of their last bits (1e-9 m) from the chain of transforms
    np.testing.assert_allclose(p.exterior[:, :3], ext[:, :3], rtol=0, atol=5e-9)
    np.testing.assert_allclose(p.exterior[:, 3:], ext[:, 3:], rtol=0, atol=1e-12)
    assert p.sensor("0").calibration == cal


def test_crs_of_other_datums_is_left_unset(tmp_path, sim):
    """A chunk in a CRS of another datum (DHDN / Gauss-Krueger zone 3) is geocentric, but
    Metashape does not say whose: no CRS is claimed."""
    pyproj = pytest.importorskip("pyproj")
    truth, cal = sim
    for code, crs, form in (("EPSG:31467", None, "WKT1_GDAL"),
                            ("EPSG:32633", "EPSG:4978", "WKT1_GDAL"),
                            ("EPSG:32633", "EPSG:4978", "WKT2_2019"),
                            ("EPSG:4979", "EPSG:4978", "WKT2_2019")):  # fmt: skip
        wkt = pyproj.CRS(code).to_wkt(form)
        text, _ = export_xml(_labels(truth), _world(truth, ECEF), cal, chunk=CHUNK, reference=wkt)
        p = _write(tmp_path, text)
        assert p.frame == "geocentric" and p.crs == crs


def test_round_trip_local_and_internal(tmp_path, sim):
    truth, cal = sim
    ext = truth.exterior
    for chunk, reference, frame in (((*CHUNK[:2], np.zeros(3)), LOCAL, "local"),
                                    (None, "", "internal")):  # fmt: skip
        text, _ = export_xml(_labels(truth), ext, cal, chunk=chunk, reference=reference)
        (tmp_path / "c.xml").write_text(text)
        p = read_metashape_cameras(tmp_path / "c.xml")
        assert p.frame == frame and p.crs is None
        np.testing.assert_allclose(p.exterior, ext, rtol=0, atol=1e-9)


def test_projection_matches_opencv(tmp_path, sim):
    cv2 = pytest.importorskip("cv2")
    truth, cal = sim
    cal = replace(cal, b1=1.5, cx=12.5, cy=-8.25, p1=4e-4, p2=-3e-4)  # every OpenCV term
    offset = np.array([500.0, -300.0, 20.0])
    chunk = (1.7, _rot(0.1, 0.2, -0.3), np.array([100.0, 50.0, -10.0]))
    text, world = export_xml(
        _labels(truth), _world(truth, offset), cal, chunk=chunk, component=COMPONENT
    )
    (tmp_path / "cameras.xml").write_text(text)
    block = truth.with_calibrations({truth.camera_ids[0].item(): cal})
    new, info = start_from_metashape(block, read_metashape_cameras(tmp_path / "cameras.xml"))
    assert info.dropped_points == 0 and new.n_points == truth.n_points
    uv, _ = projected_pixels(new)
    K, dist = cal.to_opencv()
    for i in range(new.n_images):  # images: one projectPoints call each
        A = np.linalg.inv(world[i])  # world -> camera, from the file's matrices
        A[:3, :3] /= np.cbrt(np.linalg.det(A[:3, :3]))  # a rotation; t scaled alike below
        Rcw = A[:3, :3]
        C = world[i][:3, 3]
        rvec = Rotation.from_matrix(Rcw).as_rotvec()  # cv2.Rodrigues(matrix) loses 1e-9
        tvec = -Rcw @ C
        rows = np.flatnonzero(new.obs_image == i)
        X = new.xyz[new.obs_point[rows]]
        ref, _ = cv2.projectPoints(X.reshape(-1, 1, 3), rvec, tvec, K, dist)
        np.testing.assert_allclose(uv[rows], ref.reshape(-1, 2), rtol=0, atol=1e-9)


def test_start_and_adjust(tmp_path, sim):
    """A block of tie points in its own frame (a COLMAP model: another origin, scale and
    rotation) started from the export is the truth moved into the export's world frame;
    its adjustment converges there."""
    truth, cal = sim
    text, _ = export_xml(_labels(truth), _world(truth, ECEF), cal, chunk=CHUNK)
    (tmp_path / "cameras.xml").write_text(text)
    other = truth.replace(
        exterior=np.column_stack([truth.exterior[:, :3] * 0.1, np.zeros((truth.n_images, 3))]),
        xyz=truth.xyz * 0.1 + 7.0,
    )
    new, info = start_from_metashape(other, read_metashape_cameras(tmp_path / "cameras.xml"))
    assert new.crs == "EPSG:4978" and info.frame == "geocentric"
    assert new.camera_ids.tolist() == [0] and new.calibrations[0] == cal
    assert info.rms_px < 1e-6 and info.dropped_points == 0
    np.testing.assert_allclose(new.xyz, truth.xyz + ECEF, rtol=0, atol=1e-6)
    fit = bundle_adjust(new, datum="free", free=())
    assert fit.converged
    np.testing.assert_allclose(fit.block.exterior[:, :3], truth.exterior[:, :3] + ECEF, atol=1e-5)


def test_labels_match_file_names():
    rows = match_labels(
        ["images/DJI_0001.JPG", "DJI_0002.jpg", "C:\\f\\DJI_0003.JPG", 4],
        ["DJI_0002", "DJI_0001", "4", "DJI_0003.JPG"],
    )
    assert rows.tolist() == [1, 0, 3, 2]
    assert match_labels(["x.JPG"], ["y"]).tolist() == [-1]
    with pytest.raises(InputError, match=r"a.jpg, a.png all match the Metashape camera 'a'"):
        match_labels(["a.jpg", "a.png"], ["a"])


def _write(tmp_path, text):
    (tmp_path / "cameras.xml").write_text(text)
    return read_metashape_cameras(tmp_path / "cameras.xml")


def test_refusals(tmp_path, sim):
    truth, cal = sim
    labels = _labels(truth)
    ext = _world(truth, ECEF)
    block = truth
    p = _write(tmp_path, export_xml(labels, ext, cal, chunk=CHUNK, unaligned=labels[2:4])[0])
    assert p.aligned.tolist() == [True, True, False, False] + [True] * (len(labels) - 4)
    assert np.all(np.isnan(p.exterior[2:4]))
    with pytest.raises(InputError, match=r"2 image.* not aligned .*: 2, 3;"):
        start_from_metashape(block, p)
    text = export_xml(labels, ext, cal, chunk=CHUNK)[0]
    p = _write(tmp_path, text.replace('id="3" sensor_id="0"', 'id="3" master_id="2" sensor_id="0"'))
    assert p.master_ids.tolist() == ["", "", "", "2"] + [""] * (len(labels) - 4)
    with pytest.raises(InputError, match=r"1 image.* multi-camera system .*: 3 \(master_id 2"):
        start_from_metashape(block, p)
    p = _write(tmp_path, export_xml(labels[1:], ext[1:], cal, chunk=CHUNK)[0])
    with pytest.raises(InputError, match=r"1 image.* match no camera label .*: 0;"):
        start_from_metashape(block, p)
    p = _write(tmp_path, export_xml(labels, ext, cal, chunk=CHUNK, sensor_type="fisheye")[0])
    with pytest.raises(FileFormatError, match="'fisheye' camera"):
        start_from_metashape(block, p)
    p = _write(tmp_path, export_xml(labels, ext, cal, orientation={labels[1]: 6})[0])
    with pytest.raises(InputError, match=r"EXIF orientation other than 1 .*: 1;"):
        start_from_metashape(block, p)
    p = _write(tmp_path, export_xml(labels, ext, replace(cal, width=4032), chunk=CHUNK)[0])
    with pytest.raises(InputError, match=r"4000 x 3000 px in the block .* 4032 x 3000"):
        start_from_metashape(block, p)
    p = _write(tmp_path, export_xml(labels, ext, cal, chunk=CHUNK)[0])
    role = np.where(np.arange(block.n_points) < 3, "control", "tie")
    with pytest.raises(InputError, match="3 control/check point"):
        start_from_metashape(block.replace(role=role, point_sigma=np.ones((block.n_points, 3))), p)


def test_disabled_and_fixed(tmp_path, sim):
    truth, cal = sim
    labels = _labels(truth)
    block = truth
    text, _ = export_xml(labels, truth.exterior, cal, disabled=labels[:1], fixed=True)
    p = _write(tmp_path, text)
    assert p.enabled.tolist() == [False] + [True] * (len(labels) - 1)
    new, info = start_from_metashape(block, p)
    assert info.disabled == (0,) and info.fixed == ("0",)
    assert new.free[0] == ()
    np.testing.assert_allclose(new.exterior, truth.exterior, atol=1e-9)


def test_a_mirroring_chunk_transform_is_named_a_reflection(tmp_path, sim):
    # a chunk <transform> of 16 numbers whose 3 x 3 part mirrors (det < 0) was refused as
    # "singular"; a singular one (det 0) is still called so
    truth, cal = sim
    text, _ = export_xml(_labels(truth), truth.exterior, cal, chunk=(2.0, np.eye(3), np.zeros(3)))
    k = text.rindex("<transform><rotation")
    end = text.index("</transform>", k) + len("</transform>")
    for diag, why in (("-2 2 2", r"mirrors \(det -8 < 0\)"), ("0 2 2", r"is singular")):
        d = diag.split()
        tf = f"<transform>{d[0]} 0 0 0 0 {d[1]} 0 0 0 0 {d[2]} 0 0 0 0 1</transform>"
        with pytest.raises(FileFormatError, match=rf"line \d+: the <transform> of the chunk {why}"):
            _write(tmp_path, text[:k] + tf + text[end:])


def test_malformed(tmp_path, sim):
    truth, cal = sim
    labels = _labels(truth)
    text, _ = export_xml(labels, truth.exterior, cal)
    bad = text.replace(f'label="{labels[1]}"', f'label="{labels[0]}"')
    with pytest.raises(FileFormatError, match="two cameras have the label '0'"):
        _write(tmp_path, bad)
    k = text.index("<transform>") + len("<transform>")
    with pytest.raises(FileFormatError, match=r"line \d+: the rotation of camera '0'"):
        _write(tmp_path, text[:k] + "2" + text[k:])
    k = text.index("<transform>", text.index('label="5"')) + len("<transform>")
    with pytest.raises(FileFormatError, match=r"line \d+: the <transform> of camera '5' holds a"):
        _write(tmp_path, text[:k] + "x" + text[k:])
    with pytest.raises(FileFormatError, match="camera '5' holds 17 numbers, expected 16"):
        _write(tmp_path, text[:k] + "1 " + text[k:])
    with pytest.raises(FileFormatError, match="not a Metashape camera export"):
        _write(tmp_path, "<calibration><projection>frame</projection></calibration>")


def test_cli_bundle_adjust_start_metashape(tmp_path, sim, cli):
    truth, cal = sim
    cal = replace(cal, k4=0.0)
    labels = _labels(truth)
    model = truth.replace(  # COLMAP's frame: another scale
        exterior=np.column_stack([truth.exterior[:, :3] * 0.5, truth.exterior[:, 3:]]),
        xyz=truth.xyz * 0.5,
    )
    write_colmap(model.with_calibrations({model.camera_ids[0].item(): cal}), tmp_path / "sparse")
    text, _ = export_xml(labels, _world(truth, ECEF), cal, chunk=CHUNK)
    xml = tmp_path / "cameras.xml"
    xml.write_text(text)
    sparse = tmp_path / "sparse"
    code, out, err = cli("bundle", "adjust", sparse, "--start", "metashape", "--start-file",
                         xml, "--json", "--datum", "free", "--free", "none")  # fmt: skip
    assert code == 0, err
    d = json.loads(out)
    assert d["input"]["start"] == "metashape"
    s = d["input"]["start_metashape"]
    assert s["n_images"] == 8 and s["frame"] == "geocentric" and s["rms_px"] < 1e-6
    code, out, err = cli("bundle", "adjust", sparse, "--start", "metashape", "--start-file",
                         xml, "--datum", "free", "--crs", "EPSG:32633")  # fmt: skip
    assert code == 2 and "geocentric coordinates of" in err and "(EPSG:4978)" in err, err
    code, out, err = cli("bundle", "adjust", sparse, "--start", "metashape")
    assert code == 2 and "give it with --start-file cameras.xml" in err
    code, out, err = cli("bundle", "adjust", sparse, "--start-file", xml)
    assert code == 2 and "--start-file is for --start metashape" in err


def test_camera_export_is_no_block(tmp_path, sim, cli):
    truth, cal = sim
    text, _ = export_xml(_labels(truth), truth.exterior, cal)
    (tmp_path / "cameras.xml").write_text(text)
    for cmd in (("adjust",), ("convert", tmp_path / "b.out")):
        code, _, err = cli("bundle", cmd[0], tmp_path / "cameras.xml", *cmd[1:])
        assert code == 2, err
        assert "holds poses and calibrations but no tie points" in err
        assert "--start metashape --start-file" in err
