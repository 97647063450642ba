"""Files exchanged with other tools: what real files of the peers hold."""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.bundle import read_colmap, write_colmap
from photogeom.bundle.block import Block
from photogeom.camera.metashape import MetashapeCalibration
from photogeom.errors import FileFormatError, InputError

# --- COLMAP: POINT3D_ID is a uint64; ids beyond 2^53 are not float64 numbers ----------------

BIG = 2**53 + 1  # the first integer float64 cannot hold: float(BIG) == BIG - 1


def _colmap_dir(tmp_path, images, points):
    (tmp_path / "cameras.txt").write_text("1 SIMPLE_PINHOLE 100 80 90 50 40\n")
    (tmp_path / "images.txt").write_text(images)
    (tmp_path / "points3D.txt").write_text(points)
    return tmp_path


def test_colmap_point_ids_beyond_2_53_are_read_exactly(tmp_path):
    # one id that float64 rounds to BIG - 1 (was read as 9007199254740992, silently)
    d = _colmap_dir(
        tmp_path,
        f"1 1 0 0 0 0 0 5 1 a.jpg\n10 20 {BIG} 30 40 -1\n2 1 0 0 0 1 0 5 1 b.jpg\n11 21 {BIG}\n",
        f"{BIG} 0 0 20 0 0 0 -1 1 0 2 0\n",
    )
    b = read_colmap(d)
    assert b.point_ids.tolist() == [BIG]
    assert b.observations.point_ids.tolist() == [BIG, BIG]


def test_colmap_round_trip_of_point_ids_beyond_2_53(tmp_path):
    cal = MetashapeCalibration(100, 80, 90.0)
    pid = [BIG, BIG + 1, BIG + 2]  # three ids float64 merges into two (was: "appears twice")
    b = Block.from_arrays(
        cameras={1: cal},
        image_ids=[1, 2],
        image_camera=[1, 1],
        exterior=[[0, 0, 20, 0, 0, 0], [1, 0, 20, 0, 0, 0]],
        point_ids=pid,
        xyz=[[0, 0, 0], [1, 1, 0], [-1, 1, 0]],
        obs_image_ids=[1, 1, 1, 2, 2],
        obs_point_ids=[pid[0], pid[1], pid[2], pid[0], pid[2]],
        uv=[[50, 40], [54, 36], [45, 36], [46, 40], [41, 36]],
        sigma=1.0,
    )
    write_colmap(b, tmp_path)
    back = read_colmap(tmp_path, image_key="id")
    assert back.point_ids.tolist() == pid
    assert back.observations.point_ids.tolist() == b.observations.point_ids.tolist()
    pycolmap = pytest.importorskip("pycolmap")
    assert sorted(pycolmap.Reconstruction(str(tmp_path)).points3D) == pid


@pytest.mark.parametrize(
    ("images_id", "points_id", "match"),
    [
        ("7", "9.1e15", r"points3D.txt, line 1: POINT3D_ID '9.1e15' is not an integer"),
        ("7.5", "7", r"images.txt, line 2: POINT3D_ID '7.5' is not an integer"),
        ("7", "9223372036854775808", r"line 1: POINT3D_ID '9223372036854775808' is not an"),
        ("7", "-3", r"points3D.txt, line 1: POINT3D_ID -3 is negative"),
    ],
)
def test_colmap_point_ids_that_are_not_integers_are_named(tmp_path, images_id, points_id, match):
    d = _colmap_dir(
        tmp_path,
        f"1 1 0 0 0 0 0 5 1 a.jpg\n10 20 {images_id}\n",
        f"{points_id} 0 0 20 0 0 0 -1 1 0\n",
    )
    with pytest.raises(FileFormatError, match=match):
        read_colmap(d)


# --- LAS 1.4: extended VLRs (EVLRs) are part of the file, the CRS WKT may be one -----------


def _las14_with_evlrs(path, crs="EPSG:32633"):
    laspy = pytest.importorskip("laspy")
    pyproj = pytest.importorskip("pyproj")
    from laspy.vlrs.known import WktCoordinateSystemVlr
    from laspy.vlrs.vlr import VLR
    from laspy.vlrs.vlrlist import VLRList

    rng = np.random.default_rng(3)
    xyz = rng.uniform([500000, 5e6, 0], [500100, 5e6 + 100, 50], size=(200, 3))
    h = laspy.LasHeader(point_format=6, version="1.4")
    h.scales, h.offsets = [0.01] * 3, [500000, 5e6, 0]
    las = laspy.LasData(h)
    las.x, las.y, las.z = xyz.T
    las.header.global_encoding.wkt = True
    las.evlrs = VLRList(
        [
            WktCoordinateSystemVlr(pyproj.CRS(crs).to_wkt()),
            VLR("photogeomtest", 42, "custom", b"\x01\x02" * 50),
        ]
    )
    las.write(path)
    return xyz


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_transform_cloud_keeps_evlrs_and_their_crs(tmp_path, suffix):
    laspy = pytest.importorskip("laspy")
    from photogeom.io import cloud_info, transform_cloud

    src = tmp_path / "in.las"
    _las14_with_evlrs(src)
    out = tmp_path / f"out{suffix}"
    res = transform_cloud(src, out, lambda p: p + 1.0)
    # was: no EVLR written, the output had no CRS at all (crs_name None)
    assert res.crs_name.startswith("EPSG:32633")
    assert cloud_info(out).crs_name.startswith("EPSG:32633")
    with laspy.open(out) as r:
        kinds = [(type(v).__name__, getattr(v, "user_id", "")) for v in r.header.evlrs]
        custom = [v for v in r.header.evlrs if getattr(v, "user_id", "") == "photogeomtest"]
    assert kinds[0][0] == "WktCoordinateSystemVlr" and len(kinds) == 2
    assert custom[0].record_data == b"\x01\x02" * 50


def test_transform_cloud_replaces_a_crs_held_in_an_evlr(tmp_path):
    laspy = pytest.importorskip("laspy")
    from photogeom.crs import ProjTransform
    from photogeom.io import transform_cloud

    src = tmp_path / "in.las"
    _las14_with_evlrs(src)
    out = tmp_path / "out.las"
    res = transform_cloud(src, out, ProjTransform("EPSG:32633", "EPSG:32632"))
    assert res.crs_name.startswith("EPSG:32632")
    with laspy.open(out) as r:  # one CRS record (the new one), the custom EVLR kept
        crs_records = [
            v
            for v in [*r.header.vlrs, *r.header.evlrs]
            if type(v).__name__ == "WktCoordinateSystemVlr"
        ]
        assert len(crs_records) == 1
        assert [v.user_id for v in r.header.evlrs] == ["photogeomtest"]


# --- COLMAP binary models (what COLMAP writes by default) -----------------------------------


def _small_block() -> Block:
    cal = MetashapeCalibration(100, 80, 90.0)
    return Block.from_arrays(
        cameras={1: cal},
        image_ids=[1, 2],
        image_camera=[1, 1],
        exterior=[[0, 0, 20, 0, 0, 0], [1, 0, 20, 0, 0, 0]],
        point_ids=[7, 8, 9],
        xyz=[[0, 0, 0], [1, 1, 0], [-1, 1, 0]],
        obs_image_ids=[1, 1, 1, 2, 2],
        obs_point_ids=[7, 8, 9, 7, 9],
        uv=[[50, 40], [54, 36], [45, 36], [46, 40], [41, 36]],
        sigma=1.0,
    )


def _binary_model(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    text, binary = tmp_path / "text", tmp_path / "bin"
    write_colmap(_small_block(), text)
    binary.mkdir()
    pycolmap.Reconstruction(str(text)).write_binary(str(binary))
    return binary


def test_a_colmap_binary_model_is_read_as_its_text_model(tmp_path):
    from photogeom.bundle import read_block

    binary = _binary_model(tmp_path)
    # was: "a COLMAP binary model (cameras.bin, ...); photogeom reads COLMAP's text model:
    # convert it first with 'colmap model_converter ...'" from read_colmap and read_block
    text = read_colmap(tmp_path / "text")
    for read in (read_colmap, read_block):
        b = read(binary)
        np.testing.assert_array_equal(b.exterior, text.exterior)
        np.testing.assert_array_equal(b.observations.uv, text.observations.uv)
        assert b.image_ids.tolist() == text.image_ids.tolist()


def test_cli_reads_a_colmap_binary_model(tmp_path, cli):
    binary = _binary_model(tmp_path)
    # was: exit code 2, "a COLMAP binary model ... model_converter", with and without --from
    for k, extra in enumerate(([], ["--from", "colmap-bin"])):
        code, out, err = cli("bundle", "convert", binary, tmp_path / f"o{k}", "--to", "csv",
                             *extra)  # fmt: skip
        assert code == 0, err
        assert "(colmap-bin)" in out and "3 points, 5 image observations" in out
    code, _, err = cli("bundle", "convert", tmp_path / "text", binary, "--to", "colmap")
    assert code == 2 and "TARGET: cannot write a COLMAP text model" in err


def test_writing_a_text_model_over_a_binary_model_is_refused(tmp_path):
    from photogeom.errors import OutputError

    binary = _binary_model(tmp_path)
    before = sorted(p.name for p in binary.iterdir())
    # was: cameras.txt, images.txt, points3D.txt written beside the .bin files, and COLMAP
    # (which reads the binary model first) kept reading the old model
    with pytest.raises(OutputError, match=r"holds a COLMAP binary model .*remove the \.bin"):
        write_colmap(_small_block(), binary)
    assert sorted(p.name for p in binary.iterdir()) == before


# --- COLMAP 3.12+: poses live in frames.txt; writing over a COLMAP model must replace it ----


def test_write_colmap_over_a_model_written_by_colmap_replaces_its_poses(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    first, model = tmp_path / "first", tmp_path / "model"
    block = _small_block()
    write_colmap(block, first)
    model.mkdir()
    pycolmap.Reconstruction(str(first)).write_text(str(model))  # with rigs.txt, frames.txt
    moved = block.exterior.copy()
    moved[:, :3] += [5.0, -3.0, 2.0]
    b2 = Block.from_arrays(
        cameras={1: block.calibrations[0]},
        image_ids=[1, 2],
        image_camera=[1, 1],
        exterior=moved,
        point_ids=[7, 8, 9],
        xyz=block.xyz,
        obs_image_ids=[1, 1, 1, 2, 2],
        obs_point_ids=[7, 8, 9, 7, 9],
        uv=block.observations.uv,
        sigma=1.0,
    )
    write_colmap(b2, model)
    rec = pycolmap.Reconstruction(str(model))
    centres = np.array([rec.images[i].projection_center() for i in (1, 2)])
    # was: COLMAP read the old frames.txt: the centres were the first block's
    np.testing.assert_allclose(centres, moved[:, :3], atol=1e-9)
    assert {"rigs.txt", "frames.txt"} <= {p.name for p in model.iterdir()}
    # and the same model read back by photogeom
    np.testing.assert_allclose(read_colmap(model, image_key="id").exterior, moved, atol=1e-12)


def test_colmap_frames_of_image_variant_cameras(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    from photogeom.bundle import projected_pixels

    block = _small_block()
    # image-variant offsets of f, cx, cy: one COLMAP camera (and rig) per image
    b = Block.from_arrays(
        cameras={1: block.calibrations[0]},
        image_ids=[1, 2],
        image_camera=[1, 1],
        exterior=block.exterior,
        point_ids=[7, 8, 9],
        xyz=block.xyz,
        obs_image_ids=[1, 1, 1, 2, 2],
        obs_point_ids=[7, 8, 9, 7, 9],
        uv=block.observations.uv,
        sigma=1.0,
        calibration_offset=[[0.0, 0.5, -0.5], [0.0, -1.0, 1.5]],
    )
    write_colmap(b, tmp_path)
    rec = pycolmap.Reconstruction(str(tmp_path))
    assert len(rec.cameras) == 2 and len(rec.rigs) == 2 and len(rec.frames) == 2
    uv, _ = projected_pixels(b)
    o = b.observations
    for k in range(len(o)):
        im = next(i for i in rec.images.values() if i.name == str(o.image_ids[k]))
        cam = rec.cameras[im.camera_id]
        got = cam.img_from_cam(im.cam_from_world() * b.xyz[b.obs_point[k]]) - 0.5
        np.testing.assert_allclose(got, uv[k], atol=1e-9)


@pytest.mark.parametrize("wkt", [True, False])
def test_replaced_crs_keeps_the_encoding_the_wkt_bit_announces(tmp_path, wkt):
    """LAS 1.4, point format 1: the CRS may be WKT (global-encoding bit set) or GeoTIFF keys
    (bit clear); the record written must be the one the bit says."""
    laspy = pytest.importorskip("laspy")
    pyproj = pytest.importorskip("pyproj")
    from photogeom.crs import ProjTransform
    from photogeom.io import transform_cloud

    h = laspy.LasHeader(point_format=1, version="1.4")
    h.scales, h.offsets = [0.01] * 3, [500000, 5e6, 0]
    h.add_crs(pyproj.CRS("EPSG:32633"), keep_compatibility=not wkt)
    assert h.global_encoding.wkt == wkt
    las = laspy.LasData(h)
    las.x, las.y, las.z = np.array([[500010.0, 5e6 + 10, 1.0], [500020.0, 5e6 + 20, 2.0]]).T
    src, out = tmp_path / "in.las", tmp_path / "out.las"
    las.write(src)
    res = transform_cloud(src, out, ProjTransform("EPSG:32633", "EPSG:32632"))
    assert res.crs_name.startswith("EPSG:32632")
    with laspy.open(out) as r:
        kinds = {type(v).__name__ for v in r.header.vlrs}
        assert r.header.global_encoding.wkt == wkt
    # was (bit set): GeoKeyDirectoryVlr written under the WKT bit, no WKT record
    assert ("WktCoordinateSystemVlr" in kinds) == wkt
    assert ("GeoKeyDirectoryVlr" in kinds) == (not wkt)


# --- Dask pieces joined into LAZ: the point format byte of LAZ has the compression bits set --


@pytest.mark.parametrize(("version", "point_format"), [("1.2", 3), ("1.4", 1), ("1.4", 6)])
def test_laz_from_dask_pieces_keeps_the_point_count(tmp_path, version, point_format):
    laspy = pytest.importorskip("laspy")
    pytest.importorskip("dask")
    from photogeom.io import read_cloud_xyz, transform_cloud

    rng = np.random.default_rng(5)
    xyz = rng.uniform([500000, 5e6, 0], [500100, 5e6 + 100, 50], size=(120_000, 3))
    h = laspy.LasHeader(point_format=point_format, version=version)
    h.scales, h.offsets = [0.01] * 3, [500000, 5e6, 0]
    las = laspy.LasData(h)
    las.x, las.y, las.z = xyz.T
    src = tmp_path / "in.las"
    las.write(src)
    seq, par = tmp_path / "seq.laz", tmp_path / "par.laz"
    transform_cloud(src, seq, lambda p: p + 1.0, chunk_size=20_000)
    transform_cloud(src, par, lambda p: p + 1.0, chunk_size=20_000, scheduler="threads")
    # was (point formats 0-5): the legacy point count of the joined LAZ file was 0, so LAS
    # 1.0-1.3 readers saw an empty cloud (read_cloud_xyz: 0 of 120 000 points)
    with open(seq, "rb") as a, open(par, "rb") as b:
        assert a.read(111)[107:] == b.read(111)[107:]
    with laspy.open(par) as r:
        assert r.header.point_count == 120_000
    np.testing.assert_array_equal(read_cloud_xyz(par), read_cloud_xyz(seq))


# --- Metashape calibration XML: the older Agisoft format is named, not "missing <f>" --------


def test_older_agisoft_calibration_xml_is_named_with_the_fix():
    import warnings

    old = (
        "<calibration><projection>frame</projection><width>4000</width><height>3000</height>"
        "<fx>3500.1</fx><fy>3499.2</fy><cx>2010.5</cx><cy>1490.2</cy><skew>0</skew>"
        "<k1>-0.1</k1><p1>0.001</p1></calibration>"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # was: an "unknown tag(s) <fx>, <fy>, <skew>" warning
        # and then "missing required tag(s) <f>"
        with pytest.raises(FileFormatError, match=r"older Agisoft format .*<fx>.*export it again"):
            MetashapeCalibration.from_xml_string(old, source="lens.xml")


@pytest.mark.parametrize(("point_format", "version"), [(6, "1.2"), (11, "1.4"), (3, "1.5")])
def test_write_cloud_names_point_formats_a_version_lacks(tmp_path, point_format, version):
    pytest.importorskip("laspy")
    from photogeom.errors import InputError
    from photogeom.io import write_cloud

    # was: laspy's LaspyException / PointFormatNotSupported("11"), not a photogeom error
    match = rf"point_format={point_format} with version='{version}'.*1\.2: 0-3"
    with pytest.raises(InputError, match=match):
        write_cloud(tmp_path / "c.las", np.zeros((3, 3)), point_format=point_format,
                    version=version)  # fmt: skip
    assert not list(tmp_path.iterdir())


# --- COLMAP models without 3D points (COLMAP's "known poses" input: empty points3D.txt) ----


def test_colmap_model_without_points_reads_and_writes(tmp_path):
    (tmp_path / "in").mkdir()
    d = _colmap_dir(
        tmp_path / "in",
        "# Image list\n1 1 0 0 0 0 0 5 1 a.jpg\n10 20 -1 30 40 -1\n2 1 0 0 0 1 0 5 1 b.jpg\n\n",
        "# 3D point list with one line of data per point:\n# Number of points: 0\n",
    )
    # was: ValueError "operands could not be broadcast together with shape (1,) (0,)"
    b = read_colmap(d, image_key="id")
    assert (b.n_images, b.n_points, b.n_observations) == (2, 0, 0)
    np.testing.assert_allclose(b.exterior[:, :3], [[0, 0, -5], [-1, 0, -5]], atol=1e-12)
    # was: ValueError "shape mismatch ... could not be broadcast to indexing result of shape (8,)"
    write_colmap(b, tmp_path / "out")
    back = read_colmap(tmp_path / "out", image_key="id")
    assert (back.n_images, back.n_points) == (2, 0)
    np.testing.assert_allclose(back.exterior, b.exterior, atol=1e-12)
    pycolmap = pytest.importorskip("pycolmap")
    rec = pycolmap.Reconstruction(str(tmp_path / "out"))
    assert (rec.num_images(), rec.num_points3D()) == (2, 0)


# --- decimal commas (spreadsheets in many locales) are refused with the fix named ------------

COMMA_HINT = r"decimal comma, which photogeom does not read: write numbers with a decimal point"


@pytest.mark.parametrize("rows", [1, 40_000])  # Python parser; pyarrow (> 256 KiB)
def test_points_with_decimal_commas_name_the_fix(tmp_path, rows):
    from photogeom.io import read_points

    body = "".join(f"{k};{k}.5;2.5;3\n" for k in range(rows - 1))
    p = tmp_path / "p.csv"
    p.write_text("id;x;y;z\n" + body + "99;1.234,5;2,5;3\n")
    # was: "column x holds '1.234,5', not a number", nothing about the decimal comma
    with pytest.raises(FileFormatError, match=rf"line {rows + 1}: column x holds '1\.234,5', "
                       rf"not a number; it has a {COMMA_HINT}"):  # fmt: skip
        read_points(p)


def test_block_files_with_decimal_commas_name_the_fix(tmp_path):
    from photogeom.bundle import read_bal, read_csv_block, write_csv_block
    from photogeom.datasets import path as dataset_path

    block = read_bal(dataset_path("dubrovnik-3-7"))
    write_csv_block(block, tmp_path / "csv")
    obs = tmp_path / "csv" / "observations.csv"
    lines = obs.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln[:1].isdigit())
    cells = lines[k].split(",")
    lines[k] = ";".join([*cells[:2], cells[2].replace(".", ","), *cells[3:]])
    lines = [ln.replace(",", ";") if i != k else ln for i, ln in enumerate(lines)]
    obs.write_text("\n".join(lines) + "\n")
    with pytest.raises(FileFormatError, match=rf"column 'u': .* is not a number; it has a "
                       rf"{COMMA_HINT}"):  # fmt: skip
        read_csv_block(tmp_path / "csv")
    bal = tmp_path / "b.txt"
    text = dataset_path("dubrovnik-3-7").read_text().replace("-3.859900e+02", "-3,859900e+02")
    bal.write_text(text)
    with pytest.raises(FileFormatError, match=rf"line 3: '-3,859900e\+02' is not a number; it "
                       rf"has a {COMMA_HINT}"):  # fmt: skip
        read_bal(bal)


# --- LAS scales are in the CRS's unit: metres -> degrees must not keep 0.01 (~1 km) --------


@pytest.mark.parametrize("scheduler", [None, "threads"])
def test_projected_to_geographic_keeps_the_resolution(tmp_path, scheduler):
    pytest.importorskip("laspy")
    if scheduler:
        pytest.importorskip("dask")
    from photogeom.crs import ProjTransform
    from photogeom.io import read_cloud_xyz, transform_cloud, write_cloud

    rng = np.random.default_rng(6)
    xyz = rng.uniform([500000, 5e6, 0], [500100, 5e6 + 100, 50], size=(500, 3))
    src = tmp_path / "utm.las"
    write_cloud(src, xyz, scales=(0.01, 0.01, 0.01), crs="EPSG:32633")
    T = ProjTransform("EPSG:32633", "EPSG:4979")
    out = tmp_path / "geo.las"
    res = transform_cloud(src, out, T, scheduler=scheduler)
    # was: scales (0.01, 0.01, 0.01) kept as degrees: all 500 points on one lon/lat
    # position, up to 0.0044 degrees (~490 m) from where PROJ put them
    np.testing.assert_array_equal(res.scales, [1e-7, 1e-7, 0.01])
    got, exact = read_cloud_xyz(out), T.apply(read_cloud_xyz(src))
    assert np.abs(got[:, :2] - exact[:, :2]).max() <= 0.5e-7 * (1 + 1e-6)
    assert np.abs(got[:, 2] - exact[:, 2]).max() <= 0.005 + 1e-9
    assert len(np.unique(got[:, :2], axis=0)) == 500
    # and back: degrees -> metres gives the metre resolution again
    back = transform_cloud(out, tmp_path / "back.las", ProjTransform("EPSG:4979", "EPSG:32633"))
    np.testing.assert_array_equal(back.scales, [0.01, 0.01, 0.01])
    # scales= given: used as given
    given = transform_cloud(src, tmp_path / "g.las", T, scales=(1e-8, 1e-8, 0.001))
    np.testing.assert_array_equal(given.scales, [1e-8, 1e-8, 0.001])


def test_unit_scales_of_transformations_without_crs_are_kept():
    from photogeom.crs import ProjTransform
    from photogeom.io.cloud import unit_scales

    same = [0.0025, 0.0025, 0.001]
    np.testing.assert_array_equal(unit_scales(same, lambda p: p), same)
    utm = ProjTransform("EPSG:32633", "EPSG:32632")  # same units: kept exactly
    np.testing.assert_array_equal(unit_scales(same, utm), same)
    feet = ProjTransform("EPSG:32618", "EPSG:2263", allow_ballpark=True)  # US survey feet
    np.testing.assert_array_equal(unit_scales([0.01, 0.01, 0.01], feet), [0.01, 0.01, 0.01])


# --- CSV blocks: integer ids beyond 64 bits are labels, not an OverflowError ----------------


def _csv_block_with_point_ids(tmp_path, new_id):
    from photogeom.bundle import read_bal, write_csv_block
    from photogeom.datasets import path as dataset_path

    d = tmp_path / "csv"
    write_csv_block(read_bal(dataset_path("dubrovnik-3-7")), d)
    for name, col in (("points.csv", 0), ("observations.csv", 1)):
        out = []
        for ln in (d / name).read_text().splitlines():
            if ln[:1].isdigit():
                cells = ln.split(",")
                cells[col] = new_id(name, cells[col])
                ln = ",".join(cells)
            out.append(ln)
        (d / name).write_text("\n".join(out) + "\n")
    return d


def test_csv_block_ids_beyond_64_bits_are_read_as_text(tmp_path):
    from photogeom.bundle import read_csv_block, write_csv_block

    d = _csv_block_with_point_ids(tmp_path, lambda _, c: str(10**20 + int(c)))
    # was: OverflowError "Python int too large to convert to C long"
    b = read_csv_block(d)
    assert b.point_ids.dtype.kind == "U" and b.point_ids[0] == str(10**20)
    assert set(b.observations.point_ids.tolist()) <= set(b.point_ids.tolist())
    write_csv_block(b, tmp_path / "again")
    again = read_csv_block(tmp_path / "again")
    assert again.point_ids.tolist() == b.point_ids.tolist()


def test_csv_block_observation_id_beyond_64_bits_is_named(tmp_path):
    from photogeom.bundle import read_csv_block

    big = str(10**20)
    d = _csv_block_with_point_ids(
        tmp_path, lambda name, c: big if name == "observations.csv" and c == "0" else c
    )
    with pytest.raises(FileFormatError, match=rf"point_id '{big}' is not one of the point"):
        read_csv_block(d)


@pytest.mark.parametrize(
    ("cameras", "images", "match"),
    [
        ("99999999999999999999 SIMPLE_PINHOLE 100 80 90 50 40\n", None,
         r"cameras.txt, line 1: CAMERA_ID 99999999999999999999 is not a COLMAP id"),
        (None, "99999999999999999999 1 0 0 0 0 0 5 1 a.jpg\n10 20 7\n",
         r"images.txt, line 1: IMAGE_ID 99999999999999999999 is not a COLMAP id"),
        (None, "1 1 0 0 0 0 0 5 4294967295 a.jpg\n10 20 7\n",
         r"images.txt, line 1: CAMERA_ID 4294967295 is not a COLMAP id .*0 to 4294967294"),
    ],
)  # fmt: skip
def test_colmap_ids_out_of_colmaps_range_are_named(tmp_path, cameras, images, match):
    d = _colmap_dir(tmp_path, images or "1 1 0 0 0 0 0 5 1 a.jpg\n10 20 7\n",
                    "7 0 0 20 0 0 0 -1 1 0\n")  # fmt: skip
    if cameras:
        (d / "cameras.txt").write_text(cameras)
    # was: OverflowError "Python int too large to convert to C long"
    with pytest.raises(FileFormatError, match=match):
        read_colmap(d)


# --- damaged block files: refused with file and line, never a raw Python error ---------------


def test_damaged_block_files_are_refused_with_file_and_line(tmp_path):
    from photogeom.bundle import read_bal, read_csv_block, write_csv_block
    from photogeom.datasets import path as dataset_path

    bal = dataset_path("dubrovnik-3-7").read_text()
    p = tmp_path / "b.txt"
    p.write_text("inf 7 19" + bal[bal.index("\n"):])
    # was: OverflowError "cannot convert float infinity to integer"
    with pytest.raises(FileFormatError, match=r"line 1: the header must be three non-negative"):
        read_bal(p)

    (tmp_path / "cm").mkdir()
    d = _colmap_dir(
        tmp_path / "cm", "1 1 0 0 0 0 0 5 1 a.jpg\n10 20 7\n", "7 0 0 20 0 0 0 -1 1 0\n"
    )
    (d / "cameras.txt").write_text(f"1 SIMPLE_PINHOLE {'1' * 400} 80 90 50 40\n")
    # was: OverflowError "integer division result too large for a float"
    with pytest.raises(FileFormatError, match=r"cameras.txt, line 1: camera 1: WIDTH x HEIGHT"):
        read_colmap(d)
    (d / "cameras.txt").write_text("1 SIMPLE_PINHOLE 0 80 90 50 40\n")
    with pytest.raises(FileFormatError, match=r"is not an image size"):
        read_colmap(d)

    block = read_bal(dataset_path("dubrovnik-3-7"))
    write_csv_block(block, tmp_path / "csv")
    obs = tmp_path / "csv" / "observations.csv"
    good = obs.read_text()
    lines = good.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln[:1].isdigit())
    lines[k] = "9" * 5000 + lines[k][lines[k].index(","):]
    obs.write_text("\n".join(lines) + "\n")
    # was: ValueError "Exceeds the limit (4300 digits) for integer string conversion"
    with pytest.raises(FileFormatError, match=rf"line {k + 1}: image_id '9{{40}}\.\.\.' is not"):
        read_csv_block(tmp_path / "csv")
    lines[k] = "x" * 200_000 + lines[k][lines[k].index(","):]
    obs.write_text("\n".join(lines) + "\n")
    # was: _csv.Error "field larger than field limit (131072)"; the column-wise split has
    # no field limit, so the cell is judged as an id
    with pytest.raises(FileFormatError, match=rf"line {k + 1}: image_id 'x{{40}}\.\.\.' is not"):
        read_csv_block(tmp_path / "csv")
    # a line the column-wise split cannot take (a quoted cell holding a separator) goes
    # through the csv module, whose field limit is named with file and line
    lines[k] = '"a,' + "x" * 200_000 + '"' + lines[k][lines[k].index(","):]
    obs.write_text("\n".join(lines) + "\n")
    with pytest.raises(FileFormatError, match=rf"line {k + 1}: "):
        read_csv_block(tmp_path / "csv")


def test_laz_header_count_beyond_its_chunk_table_is_refused(tmp_path):
    pytest.importorskip("laspy")
    import struct

    from photogeom.io import cloud_info, read_cloud_xyz, write_cloud

    p = tmp_path / "c.laz"
    write_cloud(p, np.random.default_rng(7).uniform(0, 100, (60_000, 3)), point_format=3,
                version="1.2")  # fmt: skip
    data = bytearray(p.read_bytes())
    struct.pack_into("<I", data, 107, 2_717_909_292)  # the legacy point count, damaged
    p.write_bytes(bytes(data))
    # was: MemoryError "Unable to allocate 60.8 GiB for an array with shape (2717909292, 3)"
    for read in (read_cloud_xyz, cloud_info):
        with pytest.raises(FileFormatError, match=r"promises 2717909292 points but its LAZ "
                           r"chunk table holds at most 100000"):  # fmt: skip
            read(p)


def test_rpc_text_with_decimal_commas_names_the_fix(tmp_path):
    from photogeom.datasets import path as dataset_path
    from photogeom.rpc import read_rpc

    text = dataset_path("ikonos").read_text()
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("LINE_OFF:"))
    lines[k] = "LINE_OFF: +005124,00 pixels"
    p = tmp_path / "x_RPC.TXT"
    p.write_text("\n".join(lines) + "\n")
    # was: "key LINE_OFF holds 2 values, expected one", nothing about the comma
    with pytest.raises(FileFormatError, match=rf"LINE_OFF holds 2 values, expected one; it has a "
                       rf"{COMMA_HINT}"):  # fmt: skip
        read_rpc(p)


@pytest.mark.parametrize("scheduler", [None, "threads"])
def test_transform_cloud_copies_header_text_that_is_not_ascii(tmp_path, scheduler):
    """LAS header strings are ASCII by the spec; real files carry UTF-8 or Latin-1 in the
    generating software or a VLR description. laspy reads them; the copy keeps the bytes."""
    pytest.importorskip("laspy")
    if scheduler:
        pytest.importorskip("dask")
    from photogeom.io import read_cloud_xyz, transform_cloud, write_cloud

    src = tmp_path / "in.las"
    write_cloud(src, np.random.default_rng(8).uniform(0, 100, (100, 3)), point_format=3,
                version="1.2", crs="EPSG:32633")  # fmt: skip
    data = bytearray(src.read_bytes())
    name = "Généré".encode()  # generating software (UTF-8), bytes 58..89
    data[58 : 58 + len(name)] = name
    vlr = int.from_bytes(data[94:96], "little")  # header size: the first VLR starts there
    data[vlr + 22 : vlr + 26] = b"\xe9t\xe9 "  # its description, Latin-1
    src.write_bytes(bytes(data))
    out = tmp_path / "out.las"
    # was: UnicodeDecodeError "'ascii' codec can't decode byte 0xc3 in position 1"
    transform_cloud(src, out, lambda p: p + 1.0, scheduler=scheduler)
    got = out.read_bytes()
    assert got[58:90] == bytes(data[58:90])
    assert got[vlr + 22 : vlr + 54] == bytes(data[vlr + 22 : vlr + 54])
    np.testing.assert_allclose(read_cloud_xyz(out), read_cloud_xyz(src) + 1.0, atol=1e-9)


@pytest.mark.parametrize(
    ("name", "n", "match"),
    [
        ("x" * 40, 3, r"extra= names dimensions of 1 to 32 bytes"),  # was: ValueError
        ("X", 3, r"point format 6 already has a dimension 'X'"),  # was: ValueError
        ("amp", 4, r"has shape \(4,\); it needs one value per point \(3,\)"),
    ],
)
def test_write_cloud_names_bad_extra_dimensions(tmp_path, name, n, match):
    pytest.importorskip("laspy")
    from photogeom.errors import InputError
    from photogeom.io import write_cloud

    with pytest.raises(InputError, match=match):
        write_cloud(tmp_path / "c.las", np.zeros((3, 3)), extra={name: np.arange(float(n))})
    assert not list(tmp_path.iterdir())


def test_damaged_las_headers_are_refused_quickly(tmp_path):
    """Found by mutating LAS headers: each was a raw laspy error, a MemoryError or a read
    of 2^31 VLRs one by one (minutes)."""
    pytest.importorskip("laspy")
    import struct

    from photogeom.io import cloud_info, read_cloud_xyz, transform_cloud, write_cloud

    good = tmp_path / "good.las"
    write_cloud(good, np.random.default_rng(9).uniform(0, 100, (50, 3)), point_format=3,
                version="1.2")  # fmt: skip
    raw = good.read_bytes()

    def damaged(name, edit):
        b = bytearray(raw)
        edit(b)
        p = tmp_path / name
        p.write_bytes(bytes(b))
        return p

    version = damaged("v.las", lambda b: b.__setitem__(24, 59))  # was: FileVersionNotSupported
    vlrs = damaged("n.las", lambda b: struct.pack_into("<I", b, 100, 2**31))  # was: a hang
    for p, match in ((version, r"LAS version 59\.2; LAS versions are 1\.0 to 1\.4"),
                     (vlrs, r"announces 2147483648 VLRs")):  # fmt: skip
        for run in (cloud_info, read_cloud_xyz,
                    lambda q: transform_cloud(q, tmp_path / "o.las", lambda x: x)):  # fmt: skip
            with pytest.raises(FileFormatError, match=match):
                run(p)
    assert not (tmp_path / "o.las").exists()


def test_a_blocks_crs_is_not_dropped_silently_by_bal_or_colmap(tmp_path):
    """BAL and COLMAP hold no CRS: a block with one was written without it, and read back as
    a block in no CRS, while control points and GNSS were refused without drop_extras."""
    import photogeom as pg
    from photogeom.bundle.io_colmap import colmap_texts

    sim = pg.simulate.uav_block(
        "FC300S", seed=1, gcps="none", checks=0, gnss_sigma=None, imu_sigma_deg=None,
        tie_points_per_image=30, brown=False,
    )  # fmt: skip
    plain = colmap_texts(sim.block)  # nothing the format cannot hold
    block = sim.block.replace(crs="EPSG:32632")
    crs = r"coordinate reference system \(EPSG:32632\)"
    with pytest.raises(InputError, match=crs + ".*drop_extras"):
        colmap_texts(block)
    with pytest.raises(InputError, match=crs):
        pg.bundle.write_bal(block, tmp_path / "b.bal")
    assert not (tmp_path / "b.bal").exists()
    assert colmap_texts(block, drop_extras=True) == plain


def _cloud_with_broken_crs(path):
    import laspy

    h = laspy.LasHeader(point_format=6, version="1.4")
    h.scales, h.offsets = [0.01] * 3, [0.0] * 3
    h.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr('PROJCS["broken", nonsense'))
    las = laspy.LasData(h)
    las.x = las.y = las.z = np.arange(5.0)
    las.write(path)
    return path


def test_an_unreadable_crs_record_is_not_shown_as_none(tmp_path, cli):
    """A CRS record that pyproj cannot parse was swallowed: cloud info said 'none recorded'
    and a PROJ transformation asked for --from-crs as if the file had no record."""
    from photogeom.io.cloud import cloud_info

    src = _cloud_with_broken_crs(tmp_path / "bad.las")
    info = cloud_info(src)
    assert info.crs is None and "broken" in info.crs_error
    assert info.to_dict()["crs_error"] == info.crs_error
    code, out, _ = cli("cloud", "info", src)
    assert code == 0 and "CRS: a record that cannot be read (" in out
    code, _, err = cli("cloud", "transform", src, tmp_path / "o.las", "--to-crs", "EPSG:4979")
    assert code == 2 and "its CRS record cannot be read" in err and "--from-crs" in err
    assert not (tmp_path / "o.las").exists()


def test_parameters_are_not_applied_to_a_cloud_whose_crs_record_cannot_be_read(tmp_path):
    """--params naming the CRS they transform from: a cloud whose record cannot be read was
    taken as one without a record, so the check of its CRS was skipped."""
    from pathlib import Path

    from photogeom.cli.cloud import _check_input_crs

    src = _cloud_with_broken_crs(tmp_path / "bad.las")
    with pytest.raises(InputError, match=r"cannot be read .*EPSG:32632.*p\.json"):
        _check_input_crs(src, "EPSG:32632", Path("p.json"), False)
