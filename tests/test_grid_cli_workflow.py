"""The residual-grid workflow end to end from the command line."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg


@pytest.fixture(scope="module")
def adjusted_folder(tmp_path_factory):
    """A small simulated ILCE-7RM2 block, adjusted, written as a CSV block folder."""
    sim = pg.simulate.uav_block(
        "ILCE-7RM2", seed=2, strips=1, images_per_strip=4, tie_points_per_image=150
    )
    fit = pg.bundle_adjust(sim.block, snooping=False)
    d = tmp_path_factory.mktemp("block") / "adjusted"
    pg.bundle.write_csv_block(fit.block, d)
    return d


def test_grid_fit_takes_an_adjusted_block_and_fits_the_grids_of_grid_evaluate(
    cli, adjusted_folder, tmp_path
):
    # the grids file of a block: before, 'grid fit' read only a residuals CSV, which no
    # command writes, so a block's grids could not reach 'correct-images' from the CLI
    out = tmp_path / "grids.npz"
    code, text, err = cli(
        "grid", "fit", adjusted_folder, "--spacing", "1000", "-o", out, "--folds", "0", "--json"
    )
    assert code == 0, err
    assert out.is_file()
    block = pg.bundle.read_block(adjusted_folder)
    want = pg.calibration.fit_residual_grids(block, 1000, folds=0)  # what 'evaluate' fits
    got = pg.calibration.load_grids(out)
    assert list(got) == list(want)
    for k, g in want.items():
        np.testing.assert_allclose(got[k].nodes, g.nodes, rtol=0, atol=1e-12)
        assert got[k].image_size == g.image_size
    assert set(json.loads(text)["images"]) == {str(k) for k in want}
    # the grids read back into the next step: the block's observations corrected
    corrected = tmp_path / "corrected.csv"
    code, _, err = cli("grid", "apply", out, adjusted_folder / "observations.csv", "-o", corrected)
    assert code == 0, err


def test_grid_fit_of_a_block_options(cli, adjusted_folder, tmp_path):
    out = tmp_path / "g.json"
    code, _, err = cli(
        "grid", "fit", adjusted_folder, "--image-size", "100x100", "--spacing", "1000", "-o", out
    )
    assert code == 2 and "--image-size applies to a residuals CSV" in err
    assert not out.exists()
    code, _, err = cli(
        "grid", "fit", adjusted_folder, "--spacing", "1000", "-o", out, "--folds", "0",
        "--sigma-constraint", "0.5", "--sigma-obs", "0.3",
    )  # fmt: skip
    assert code == 0, err
    block = pg.bundle.read_block(adjusted_folder)
    want = pg.calibration.fit_residual_grids(
        block, 1000, folds=0, sigma_obs=0.3, sigma_constraint=0.5
    )
    got = pg.calibration.load_grids(out)
    for k, g in want.items():
        np.testing.assert_allclose(got[k].nodes, g.nodes, rtol=0, atol=1e-12)


def test_grid_fit_of_a_csv_needs_the_image_size_and_takes_scaled(cli, tmp_path):
    rng = np.random.default_rng(3)
    uv = rng.uniform([0, 0], [299, 199], (200, 2))
    lines = ["image_id,u,v,rx,ry"] + [f"a,{u},{v},{0.01 * u},{-0.02 * v}" for u, v in uv]
    src = tmp_path / "res.csv"
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "g.npz"
    code, _, err = cli("grid", "fit", src, "-o", out)
    assert code == 2 and "--image-size WIDTHxHEIGHT" in err
    code, _, err = cli("grid", "fit", tmp_path / "nowhere", "-o", out)  # not: --image-size
    assert code == 2 and "nowhere: no such file or folder" in err
    code, _, err = cli(
        "grid", "fit", src, "-o", out, "--image-size", "300x200", "--spacing", "50",
        "--sigma-constraint", "scaled", "--folds", "0",
    )  # fmt: skip
    assert code == 0, err
    g = pg.calibration.load_grids(out)["a"]
    assert g.sigma_constraint == pytest.approx(0.1 * 0.5**2)


def _small_grids_and_folder(tmp_path):
    """A grid for a 60 x 40 px image and a folder holding that image as PNG."""
    import cv2

    rng = np.random.default_rng(5)
    uv = rng.uniform([0, 0], [59, 39], (60, 2))
    grid = pg.calibration.fit_grid(uv, np.full((60, 2), 0.5), (60, 40), 20, folds=0)
    src = tmp_path / "images"
    src.mkdir()
    cv2.imwrite(str(src / "a.png"), np.arange(2400, dtype=np.uint8).reshape(40, 60))
    grids_file = tmp_path / "g.npz"
    pg.calibration.save_grids(grids_file, {"a": grid})
    return grids_file, src


def test_correct_images_output_folder_that_cannot_be_created_is_a_named_error(cli, tmp_path):
    # before: a traceback (FileExistsError / NotADirectoryError from mkdir) and exit code 1,
    # the code of "some images failed"
    grids_file, src = _small_grids_and_folder(tmp_path)
    in_the_way = tmp_path / "taken"
    in_the_way.write_text("a file")
    for dst in (in_the_way, in_the_way / "sub"):
        code, _, err = cli("grid", "correct-images", grids_file, src, dst)
        assert code == 2, err
        assert err.startswith("error: output folder") and "Traceback" not in err
        assert "choose another output folder" in err
    assert in_the_way.read_text() == "a file"


def test_correct_folder_refuses_an_unwritable_output_folder_before_reading_images(
    tmp_path, monkeypatch
):
    import os

    import photogeom.calibration.images as images
    from photogeom.errors import OutputError

    grids_file, src = _small_grids_and_folder(tmp_path)
    dst = tmp_path / "out"
    dst.mkdir()
    real = os.access
    monkeypatch.setattr(  # as for a user without write permission (tests may run as root)
        images.os, "access", lambda p, m: False if Path(p) == dst else real(p, m)
    )
    monkeypatch.setattr(images, "_read", lambda p: pytest.fail("an image was read"))
    with pytest.raises(OutputError, match="is not writable"):
        pg.calibration.correct_folder(src, dst, pg.calibration.load_grids(grids_file))
    assert list(dst.iterdir()) == []


def test_correct_folder_equal_folders_refused_before_anything_is_made(tmp_path):
    from photogeom.errors import InputError

    grids_file, src = _small_grids_and_folder(tmp_path)
    with pytest.raises(InputError, match="must differ"):
        pg.calibration.correct_folder(src, src / ".", pg.calibration.load_grids(grids_file))
    assert sorted(p.name for p in src.iterdir()) == ["a.png"]


def test_grid_evaluate_takes_the_grids_file_that_corrects_the_images(
    cli, adjusted_folder, tmp_path
):
    # before: 'grid evaluate' and 'grid report' fitted their own grids only, so the grids
    # file given to 'correct-images' could not be re-adjusted and evaluated from the CLI
    grids = tmp_path / "g.json"
    code, _, err = cli("grid", "fit", adjusted_folder, "--spacing", "1000", "-o", grids)
    assert code == 0, err
    code, from_file, err = cli("grid", "evaluate", adjusted_folder, "--grids", grids, "--json")
    assert code == 0, err
    code, fitted, err = cli("grid", "evaluate", adjusted_folder, "--spacing", "1000", "--json")
    assert code == 0, err
    assert json.loads(from_file) == json.loads(fitted)
    out = tmp_path / "r.html"
    code, _, err = cli(
        "grid", "report", adjusted_folder, "--grids", grids, "--spacings", "500,1000", "-o", out
    )
    assert code == 0, err
    assert out.read_text().count("<img") == 4


def test_grid_evaluate_grids_refusals(cli, adjusted_folder, tmp_path):
    grids = tmp_path / "g.npz"
    other = {"x": pg.calibration.fit_grid(np.full((5, 2), 10.0), np.zeros((5, 2)), (60, 40), 20)}
    pg.calibration.save_grids(grids, other)
    code, _, err = cli("grid", "evaluate", adjusted_folder, "--grids", grids)
    assert code == 2 and "give --grids a file with a grid for every image" in err
    code, _, err = cli("grid", "evaluate", adjusted_folder, "--grids", grids, "--spacing", "300")
    assert code == 2 and "leave them out" in err
    code, _, err = cli("grid", "evaluate", adjusted_folder, "--grids", grids, "--in-adjustment")
    assert code == 2 and "give one of them" in err
    code, _, err = cli("grid", "evaluate", adjusted_folder, "--grids", tmp_path / "none.npz")
    assert code == 2 and "does not exist" in err


def test_grid_fit_exclude_leaves_out_an_image_with_too_few_residuals(cli, tmp_path):
    # before: the error said "leave the image out", which a block could not do from the CLI
    rng = np.random.default_rng(4)
    uv = rng.uniform([0, 0], [299, 199], (40, 2))
    rows = [f"a,{u},{v},0.1,0.2" for u, v in uv] + ["b,10,10,0.1,0.1", "b,20,20,0.1,0.1"]
    src = tmp_path / "res.csv"
    src.write_text("image_id,u,v,rx,ry\n" + "\n".join(rows) + "\n")
    out = tmp_path / "g.npz"
    base = ("grid", "fit", src, "-o", out, "--image-size", "300x200", "--spacing", "50")
    code, _, err = cli(*base, "--folds", "0")
    assert code == 2 and "image b" in err and "leave the image out with --exclude ID" in err
    assert not out.exists()
    code, _, err = cli(*base, "--folds", "0", "--exclude", "b")
    assert code == 0, err
    assert list(pg.calibration.load_grids(out)) == ["a"]
    # an id given twice is left out once (a KeyError traceback before)
    code, _, err = cli(*base, "--folds", "0", "--exclude", "b,b")
    assert code == 0, err
    assert list(pg.calibration.load_grids(out)) == ["a"]
    code, _, err = cli(*base, "--exclude", "c")
    assert code == 2 and "--exclude: no image c" in err
    code, _, err = cli(*base, "--exclude", "a,b")
    assert code == 2 and "leaves no image" in err


def test_grid_fit_exclude_on_a_block(cli, adjusted_folder, tmp_path):
    out = tmp_path / "g.npz"
    block = pg.bundle.read_block(adjusted_folder)
    ids = block.image_ids.tolist()
    code, _, err = cli(
        "grid", "fit", adjusted_folder, "--spacing", "1000", "-o", out, "--folds", "0",
        "--exclude", str(ids[1]),
    )  # fmt: skip
    assert code == 0, err
    assert list(pg.calibration.load_grids(out)) == [k for k in ids if k != ids[1]]


def test_correct_folder_names_ambiguous_and_unsupported_files(tmp_path):
    # before: both were "no image file named a (or a.<ext>)", though a.png and a.tif were
    # there (two candidates) or b.bmp was (a format not read)
    import shutil

    grids_file, src = _small_grids_and_folder(tmp_path)
    shutil.copy(src / "a.png", src / "a.tif")
    (src / "b.bmp").write_bytes(b"BM")
    grids = pg.calibration.load_grids(grids_file)
    grids["b"] = grids["a"]
    res = pg.calibration.correct_folder(src, tmp_path / "out", grids, progress=False)
    assert not res.written
    assert "matches 2 files" in res.failures["a"] and "a.png, a.tif" in res.failures["a"]
    assert "in a supported format" in res.failures["b"] and "b.bmp" in res.failures["b"]
    assert list((tmp_path / "out").iterdir()) == []


@pytest.mark.parametrize("outside", ["replicate", "constant", "reflect"])
def test_correct_images_outside_option_reaches_the_remap(cli, tmp_path, outside):
    # before: correct_image had border= but correct_image_file, correct_folder and
    # 'grid correct-images' always replicated the edge
    import cv2

    rng = np.random.default_rng(6)
    uv = rng.uniform([0, 0], [59, 39], (80, 2))
    grid = pg.calibration.fit_grid(uv, np.tile([3.0, 0.0], (80, 1)), (60, 40), 20, folds=0)
    src = tmp_path / "images"
    src.mkdir()
    img = (np.arange(60, dtype=np.uint8)[None, :] * 4 + 10).repeat(40, axis=0)
    cv2.imwrite(str(src / "a.png"), img)
    grids_file = tmp_path / "g.npz"
    pg.calibration.save_grids(grids_file, {"a": grid})
    dst = tmp_path / "out"
    code, _, err = cli("grid", "correct-images", grids_file, src, dst, "--outside", outside)
    assert code == 0, err
    got = cv2.imread(str(dst / "a.png"), cv2.IMREAD_UNCHANGED)
    want = pg.calibration.correct_image(img, grid, border=outside)
    np.testing.assert_array_equal(got, want)
    assert (got[:, 0] == 0).all() == (outside == "constant")


def test_correct_folder_border_in_worker_processes(tmp_path):
    import cv2

    grids_file, src = _small_grids_and_folder(tmp_path)
    grids = pg.calibration.load_grids(grids_file)
    res = pg.calibration.correct_folder(
        src, tmp_path / "out", grids, workers=2, border="constant", progress=False
    )
    assert res.ok, res.failures
    img = cv2.imread(str(src / "a.png"), cv2.IMREAD_UNCHANGED)
    got = cv2.imread(str(tmp_path / "out" / "a.png"), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(
        got, pg.calibration.correct_image(img, grids["a"], border="constant")
    )
    with pytest.raises(pg.errors.InputError, match="border must be one of"):
        pg.calibration.correct_folder(src, tmp_path / "o2", grids, border="wrap")


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    import struct
    import zlib

    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _metadata_notes(res) -> dict:
    """The notes of a folder's result but the orientation note (an image with EXIF
    orientation 6, corrected as stored: said, with its metadata kept)."""
    kept = {k: [n for n in v.split("; ") if not n.startswith("EXIF orientation")]
            for k, v in res.notes.items()}  # fmt: skip
    return {k: v for k, v in kept.items() if v}


def test_png_metadata_kept_for_16_bit_colour_and_after_the_image_data(tmp_path):
    # before: a 16-bit colour PNG was written by OpenCV without its EXIF (orientation), ICC
    # profile, resolution and XMP (a note said so); an 8-bit PNG whose eXIf and text chunks
    # follow the image data lost them without a note (Pillow reads them only on decoding)
    import struct
    import zlib

    import cv2
    from PIL import Image, ImageCms

    rng = np.random.default_rng(7)
    uv = rng.uniform([0, 0], [59, 39], (80, 2))
    grid = pg.calibration.fit_grid(uv, np.tile([0.7, -0.4], (80, 1)), (60, 40), 20, folds=0)
    exif = Image.Exif()
    exif[274], exif[271] = 6, "ILCE-7RM2"
    icc = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    xmp = b'<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF/></x:xmpmeta>'
    early = [
        _png_chunk(b"iCCP", b"sRGB profile\x00\x00" + zlib.compress(icc)),
        _png_chunk(b"pHYs", struct.pack(">IIB", 11811, 11811, 1)),  # 300 dpi
        _png_chunk(b"iTXt", b"XML:com.adobe.xmp\x00\x00\x00\x00\x00" + xmp),
    ]
    late = [_png_chunk(b"eXIf", exif.tobytes()), _png_chunk(b"tEXt", b"Software\x00flight-tool")]
    src = tmp_path / "images"
    src.mkdir()
    images = {
        "rgb16": rng.integers(0, 65535, (40, 60, 3)).astype(np.uint16),
        "rgb8": rng.integers(0, 255, (40, 60, 3)).astype(np.uint8),
    }
    for name, pixels in images.items():
        png = cv2.imencode(".png", pixels)[1].tobytes()
        head, iend = 33, png.rindex(b"IEND") - 4  # after IHDR; the IEND chunk
        (src / f"{name}.png").write_bytes(
            png[:head] + b"".join(early) + png[head:iend] + b"".join(late) + png[iend:]
        )
    dst = tmp_path / "out"
    res = pg.calibration.correct_folder(src, dst, {k: grid for k in images}, progress=False)
    assert res.ok and not _metadata_notes(res), (res.failures, res.notes)
    for name, pixels in images.items():
        got = cv2.imread(str(dst / f"{name}.png"), cv2.IMREAD_UNCHANGED)
        assert got.dtype == pixels.dtype and got.shape == pixels.shape
        np.testing.assert_array_equal(got, pg.calibration.correct_image(pixels, grid))
        with Image.open(dst / f"{name}.png") as im:
            im.load()
            assert im.getexif()[274] == 6 and im.getexif()[271] == "ILCE-7RM2"
            assert im.info["icc_profile"] == icc
            assert im.info["dpi"] == pytest.approx((300, 300), abs=0.01)
            assert im.info["XML:com.adobe.xmp"].encode() == xmp
            assert im.info["Software"] == "flight-tool"
        data = (dst / f"{name}.png").read_bytes()
        assert data.index(b"eXIf") < data.index(b"IDAT")  # where readers look for it


def test_tiff_16_bit_colour_keeps_orientation_resolution_icc_xmp(tmp_path):
    # before: written by OpenCV without any of them (a note said so); now the original's tags
    # are grafted onto OpenCV's file, the compression kept
    import tifffile
    from PIL import Image, ImageCms

    rng = np.random.default_rng(8)
    uv = rng.uniform([0, 0], [59, 39], (80, 2))
    grid = pg.calibration.fit_grid(uv, np.tile([0.6, 0.3], (80, 1)), (60, 40), 20, folds=0)
    pixels = rng.integers(0, 65535, (40, 60, 3)).astype(np.uint16)
    icc = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    xmp = b'<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF/></x:xmpmeta>'
    src = tmp_path / "images"
    src.mkdir()
    tifffile.imwrite(
        src / "a.tif", pixels, photometric="rgb", compression="zlib", resolution=(300, 300),
        resolutionunit="INCH", metadata=None,
        extratags=[
            (274, "H", 1, 6, True), (34675, "B", len(icc), icc, True),
            (700, "B", len(xmp), xmp, True), (271, "s", 0, "Sony", True),
        ],
    )  # fmt: skip
    dst = tmp_path / "out"
    res = pg.calibration.correct_folder(src, dst, {"a": grid}, progress=False)
    assert res.ok and not _metadata_notes(res), (res.failures, res.notes)
    with tifffile.TiffFile(dst / "a.tif") as t:
        tags = {tag.code: tag.value for tag in t.pages[0].tags.values()}
        got = t.pages[0].asarray()  # as stored (the orientation is not applied)
    assert got.dtype == np.uint16
    np.testing.assert_array_equal(got, pg.calibration.correct_image(pixels, grid))
    assert tags[274] == 6 and tags[271] == "Sony" and tags[259] == 8
    assert tags[282] == (300, 1) and tags[283] == (300, 1) and tags[296] == 2
    assert bytes(tags[34675]) == icc and bytes(tags[700]) == xmp
    with Image.open(dst / "a.tif") as im:
        assert im.info["icc_profile"] == icc and im.info["dpi"] == (300, 300)
    # and the corrected file is read again like the original
    again = pg.calibration.correct_image_file(dst / "a.tif", tmp_path / "b.tif", grid)
    assert again.startswith("EXIF orientation 6 ") and "; " not in again  # no metadata lost


def _tiff_with_exif(pixels: np.ndarray, big_endian: bool = False) -> bytes:
    """A TIFF (one uncompressed strip) with Orientation 6, Make, an EXIF IFD (ExposureTime
    1/800 s, FocalLength 8.8 mm) and a GPS IFD (latitude ref N, altitude 123.4 m)."""
    import struct

    e = ">" if big_endian else "<"
    h, w = pixels.shape[:2]
    spp = 1 if pixels.ndim == 2 else pixels.shape[2]
    out = bytearray((b"MM\x00*" if big_endian else b"II*\x00") + b"\x00" * 4)

    def put(b: bytes) -> int:
        out.extend(b"\x00" * (len(out) % 2))
        out.extend(b)
        return len(out) - len(b)

    def ifd(entries: list) -> int:
        out.extend(b"\x00" * (len(out) % 2))
        at = len(out)
        out.extend(struct.pack(e + "H", len(entries)))
        for tag, typ, count, value in sorted(entries):
            v = struct.pack(e + "H", value) + b"\x00\x00" if typ == 3 and count == 1 else None
            v = v if v is not None else value if isinstance(value, bytes) else None
            v = v if v is not None else struct.pack(e + "I", value)
            out.extend(struct.pack(e + "HHI", tag, typ, count) + v)
        out.extend(b"\x00" * 4)
        return at

    data = pixels.astype(pixels.dtype.newbyteorder(e)).tobytes()
    strip = put(data)
    bits = put(struct.pack(e + "H" * spp, *[pixels.dtype.itemsize * 8] * spp))
    make = put(b"Sony\x00")
    expo, focal = put(struct.pack(e + "II", 1, 800)), put(struct.pack(e + "II", 88, 10))
    alt = put(struct.pack(e + "II", 1234, 10))
    exif_ifd = ifd([(33434, 5, 1, expo), (37386, 5, 1, focal)])
    gps_ifd = ifd([(1, 2, 2, b"N\x00\x00\x00"), (6, 5, 1, alt)])
    first = ifd(
        [
            (256, 3, 1, w), (257, 3, 1, h), (258, 3, spp, bits), (259, 3, 1, 1),
            (262, 3, 1, 2 if spp == 3 else 1), (271, 2, 5, make), (273, 4, 1, strip),
            (274, 3, 1, 6), (277, 3, 1, spp), (278, 3, 1, h), (279, 4, 1, len(data)),
            (284, 3, 1, 1), (34665, 4, 1, exif_ifd), (34853, 4, 1, gps_ifd),
        ]
    )  # fmt: skip
    out[4:8] = struct.pack(e + "I", first)
    return bytes(out)


def test_tiff_16_bit_colour_keeps_the_exif_and_gps_ifds(tmp_path):
    from PIL import Image

    rng = np.random.default_rng(9)
    uv = rng.uniform([0, 0], [59, 39], (80, 2))
    grid = pg.calibration.fit_grid(uv, np.tile([-0.4, 0.8], (80, 1)), (60, 40), 20, folds=0)
    pixels = rng.integers(0, 65535, (40, 60, 3)).astype(np.uint16)
    src = tmp_path / "images"
    src.mkdir()
    (src / "a.tif").write_bytes(_tiff_with_exif(pixels))
    (src / "b.tif").write_bytes(_tiff_with_exif(pixels, big_endian=True))
    dst = tmp_path / "out"
    res = pg.calibration.correct_folder(src, dst, {"a": grid, "b": grid}, progress=False)
    # big-endian: grafted too (before: not kept, with a note)
    assert not res.failures and not _metadata_notes(res)
    for name in ("a", "b"):
        with Image.open(dst / f"{name}.tif") as im:
            e = im.getexif()
            assert e[274] == 6 and e[271] == "Sony"
            assert float(e.get_ifd(0x8769)[33434]) == 1 / 800
            assert float(e.get_ifd(0x8769)[37386]) == 8.8
            assert e.get_ifd(0x8825)[1] == "N" and float(e.get_ifd(0x8825)[6]) == 123.4
    from photogeom.calibration.images import _read  # the pixels as stored, BGR

    for name in ("a", "b"):
        got, _ = _read(dst / f"{name}.tif")
        np.testing.assert_array_equal(got[..., ::-1], pg.calibration.correct_image(pixels, grid))


def test_image_and_coordinate_corrections_agree_up_to_remap_resolution():
    # docs/residual-grid.md, Resampling: the output pixel q takes the input at q - r(q); the
    # maps are exact, and OpenCV's remap rounds the source position to 1/32 px
    from dataclasses import replace

    rng = np.random.default_rng(10)
    uv = rng.uniform([0, 0], [199, 149], (50, 2))
    grid = pg.calibration.fit_grid(uv, np.zeros((50, 2)), (200, 150), 50, folds=0)
    u, v = grid.layout.node_coordinates()
    grid = replace(grid, nodes=np.stack([0.5 + 0.01 * u - 0.004 * v, 0.006 * u - 0.3], -1))
    yy, xx = np.mgrid[0:150, 0:200].astype(float)
    source = pg.calibration.correct_image(np.dstack([xx, yy]), grid)  # a ramp: its position
    q = np.column_stack([xx.ravel(), yy.ravel()])
    err = source.reshape(-1, 2) - (q - grid.evaluate(q))
    inside = ((q - grid.evaluate(q)) > 1).all(1) & ((q - grid.evaluate(q)) < [198, 148]).all(1)
    assert np.abs(err[inside]).max() <= 1 / 64 + 1e-6
    assert 0.005 < np.sqrt(np.mean(err[inside] ** 2)) < 0.011


def test_sensor_mean_residuals_uses_the_images_of_one_sensor_size():
    # before: every image's pixels were put in cells of the first camera's sensor, those of a
    # second camera of another size too (the figure 'mean residual vectors over the sensor')
    from dataclasses import replace

    from photogeom.report.grid_study import sensor_mean_residuals

    sim = pg.simulate.uav_block("FC300S", seed=3, strips=1, images_per_strip=4)
    block = sim.block
    wide = replace(block.calibrations[0], width=9000, height=6000)
    two = replace(
        block,
        camera_ids=np.array(["a", "b"], dtype=object),
        calibrations=(block.calibrations[0], wide),
        image_camera=np.array([0, 1, 0, 1]),
        free={"a": block.free[block.camera_ids[0]], "b": block.free[block.camera_ids[0]]},
        image_variant={"a": (), "b": ()},
    )
    per = pg.calibration.block_residuals(two)
    first = [k for k, c in zip(two.image_ids.tolist(), two.image_camera) if c == 0]
    uv = np.concatenate([per[k][0] for k in first])
    r = np.concatenate([per[k][1] for k in first])
    _, mean, counts = sensor_mean_residuals(two, cells=(4, 3))
    assert counts.sum() == len(uv)
    w, h = two.image_sizes()[0]
    cell = np.clip((uv[:, 1] / h * 3).astype(int), 0, 2) * 4 + np.clip(
        (uv[:, 0] / w * 4).astype(int), 0, 3
    )
    want = np.array([r[cell == k].mean(axis=0) for k in np.unique(cell)])
    np.testing.assert_allclose(mean, want, rtol=0, atol=1e-12)


def test_spacings_errors_name_the_option_typed(cli, adjusted_folder, tmp_path):
    # before: 'grid sweep --spacings 0,500' said '--spacing must be ...'; 'grid report'
    # said 'grid spacing ...' and 'sweep_spacings: give at least two spacings' (the
    # library's words) after evaluating the block; '500,500' swept one spacing twice;
    # 'grid evaluate --spacing 20000' said 'choose a spacing'
    report = ("grid", "report", adjusted_folder, "-o", tmp_path / "r.html", "--spacings")
    for args in (("grid", "sweep", adjusted_folder, "--spacings"), report):
        code, _, err = cli(*args, "0,500")
        assert code == 2 and "--spacings: every spacing must be a positive" in err, err
        code, _, err = cli(*args, "500")
        assert code == 2 and "--spacings: give at least two" in err, err
        code, _, err = cli(*args, "500,500")
        assert code == 2 and "--spacings: 500 given twice" in err, err
        code, _, err = cli(*args, "500,20000")
        assert code == 2 and "--spacings: 20000 px is larger" in err, err
        assert "choose --spacings of at most" in err
    assert not (tmp_path / "r.html").exists()
    code, _, err = cli("grid", "evaluate", adjusted_folder, "--spacing", "20000")
    assert code == 2 and "choose a --spacing of at most" in err


def test_grid_fit_writes_grids_and_report_together_or_not_at_all(cli, tmp_path):
    # before: the grids file was written, then the report failed (exit 2, the grids left)
    rng = np.random.default_rng(11)
    uv = rng.uniform([0, 0], [299, 199], (100, 2))
    src = tmp_path / "res.csv"
    src.write_text("image_id,u,v,rx,ry\n" + "".join(f"a,{u},{v},0.1,0.2\n" for u, v in uv))
    out = tmp_path / "g.npz"
    base = ("grid", "fit", src, "--image-size", "300x200", "--spacing", "50", "-o", out)
    code, _, err = cli(*base, "--report", tmp_path / "no" / "r.html")
    assert code == 2 and "--report" in err
    assert not out.exists()
    code, _, err = cli(*base, "--report", tmp_path)  # a folder
    assert code == 2 and "--report" in err and not out.exists()
    code, _, err = cli(*base, "--report", tmp_path / "r.html")
    assert code == 0, err
    assert out.is_file() and "<img" in (tmp_path / "r.html").read_text()


def test_grid_report_checks_its_output_before_evaluating(
    cli, adjusted_folder, tmp_path, monkeypatch
):
    # before: the block was evaluated and swept, then the report could not be written
    import photogeom.cli.grid_block as gb

    monkeypatch.setattr(gb, "_evaluate", lambda *a, **k: pytest.fail("evaluated"))
    code, _, err = cli(
        "grid", "report", adjusted_folder, "-o", tmp_path / "no" / "r.html", "--spacings", "1,2"
    )
    assert code == 2 and "--output: cannot write" in err
    code, _, err = cli("grid", "report", adjusted_folder, "-o", tmp_path, "--spacings", "1,2")
    assert code == 2 and "--output: cannot write" in err and "it is a folder" in err


def test_jpeg_without_a_resolution_does_not_get_72_dpi(tmp_path):
    # before: Pillow's default of 72 dpi (EXIF without XResolution, JFIF without a unit)
    # was written as the corrected JPEG's resolution (JFIF unit 1, 72 x 72)
    from PIL import Image

    grids_file, _ = _small_grids_and_folder(tmp_path)
    grid = pg.calibration.load_grids(grids_file)["a"]
    src = tmp_path / "jpegs"
    src.mkdir()
    pixels = np.random.default_rng(12).integers(0, 255, (40, 60, 3)).astype(np.uint8)
    exif = Image.Exif()
    exif[271] = "DJI"
    Image.fromarray(pixels).save(src / "a.jpg", exif=exif, quality=90)
    with_dpi = Image.Exif()
    with_dpi[282], with_dpi[283], with_dpi[296] = 350.0, 350.0, 2
    Image.fromarray(pixels).save(src / "b.jpg", exif=with_dpi, quality=90)
    res = pg.calibration.correct_folder(src, tmp_path / "out", {"a": grid, "b": grid})
    assert res.ok
    with Image.open(tmp_path / "out" / "a.jpg") as im:
        assert im.info["jfif_unit"] == 0 and im.info["jfif_density"] == (1, 1)
        assert im.getexif()[271] == "DJI"
    with Image.open(tmp_path / "out" / "b.jpg") as im:
        assert im.info["dpi"] == (350, 350)


def _report_rows(path) -> dict:
    """The rows of the HTML report's tables: first cell -> the other cells' text."""
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from html_tables import table_rows

    return table_rows(path.read_text())


def test_grid_report_shows_the_per_axis_numbers_of_grid_evaluate(cli, tmp_path):
    # before: the report showed the check points as one 3D RMSE, a number 'grid evaluate'
    # neither prints nor writes, and left out the tie points against the truth of a preset
    common = ("--preset", "ILCE-7RM2", "--strips", "1", "--images-per-strip", "4")
    code, text, err = cli("grid", "evaluate", *common, "--spacing", "1000", "--json")
    assert code == 0, err
    ev = json.loads(text)
    out = tmp_path / "r.html"
    code, _, err = cli(
        "grid", "report", *common, "--spacing", "1000", "--spacings", "500,1000", "-o", out
    )
    assert code == 0, err
    rows = _report_rows(out)
    for key, label in (("check", "check RMSE"), ("tie", "tie-point RMSE vs truth")):
        for k, ax in enumerate("XYZ"):
            before, after = rows[f"{label} {ax} (GSD)"][:2]
            # the rounding 'grid evaluate' prints (3 decimals of GSD)
            assert before == f"{ev[f'{key}_rmse_gsd_before'][k]:.3f}"
            assert after == f"{ev[f'{key}_rmse_gsd_after'][k]:.3f}"
    assert rows["mean step (GSD)"][0] == f"{ev['mean_step_before']:.3f}"


def _icc(space: bytes) -> bytes:
    """An ICC profile header (128 bytes, no tags) of colour space ``space``."""
    head = bytearray(128)
    head[0:4] = (128).to_bytes(4, "big")
    head[12:20] = b"mntr" + space
    head[36:40] = b"acsp"
    return bytes(head)


def test_icc_profile_of_another_colour_space_is_not_attached(tmp_path):
    # before: a CMYK JPEG (decoded by OpenCV as RGB) was written as RGB with its CMYK
    # profile, and a grey+alpha PNG (decoded as BGRA) as RGBA with its grey profile,
    # without a note: colour-managed viewers misread or reject such files
    import cv2
    from PIL import Image

    grids_file, _ = _small_grids_and_folder(tmp_path)
    grid = pg.calibration.load_grids(grids_file)["a"]
    src = tmp_path / "icc"
    src.mkdir()
    rgb = np.random.default_rng(13).integers(0, 255, (40, 60, 3)).astype(np.uint8)
    Image.fromarray(rgb).convert("CMYK").save(src / "cmyk.jpg", icc_profile=_icc(b"CMYK"))
    la = np.random.default_rng(14).integers(0, 255, (40, 60, 2)).astype(np.uint8)
    Image.fromarray(la, "LA").save(src / "la.png", icc_profile=_icc(b"GRAY"))
    Image.fromarray(rgb).save(src / "rgb.jpg", icc_profile=_icc(b"RGB "))
    res = pg.calibration.correct_folder(
        src, tmp_path / "out", {k: grid for k in ("cmyk", "la", "rgb")}, progress=False
    )
    # grey+alpha PNGs stay grey+alpha, so their grey profile is kept
    assert res.ok and sorted(res.notes) == ["cmyk"]
    assert all("ICC profile not kept" in n for n in res.notes.values())
    with Image.open(tmp_path / "out" / "cmyk.jpg") as im:
        assert "icc_profile" not in im.info
    with Image.open(tmp_path / "out" / "la.png") as im:
        assert im.mode == "LA" and im.info["icc_profile"] == _icc(b"GRAY")
    with Image.open(tmp_path / "out" / "rgb.jpg") as im:
        assert im.info["icc_profile"] == _icc(b"RGB ")
    assert cv2.imread(str(tmp_path / "out" / "la.png"), cv2.IMREAD_UNCHANGED).shape == (40, 60, 4)


def test_correct_images_scheduler_local_as_in_the_other_dask_commands(cli, tmp_path, monkeypatch):
    # before: '--scheduler local' (which the message of an unreachable scheduler suggests,
    # and which the other Dask commands take) was refused as 'not a scheduler address'
    import photogeom.calibration as calibration

    calls = []

    def fake(src, dst, grids, **kw):
        calls.append((kw["dask"], kw["workers"]))
        return calibration.FolderResult()

    monkeypatch.setattr(calibration, "correct_folder", fake)
    grids_file, src = _small_grids_and_folder(tmp_path)
    dst = tmp_path / "out"
    for args, want in (
        (("--scheduler", "local"), (True, 1)),
        (("--scheduler", "local", "--workers", "3"), (True, 3)),
        (("--scheduler", "local:2"), (True, 2)),
        (("--scheduler", "tcp://127.0.0.1:8786"), ("tcp://127.0.0.1:8786", 1)),
        (("--dask", "--workers", "2"), (True, 2)),
    ):
        code, _, err = cli("grid", "correct-images", grids_file, src, dst, *args)
        assert code == 0, err
        assert calls.pop() == want
    code, _, err = cli("grid", "correct-images", grids_file, src, dst, "--scheduler", "threads")
    assert code == 2 and "--workers N" in err
    code, _, err = cli("grid", "correct-images", grids_file, src, dst, "--scheduler", "foo")
    assert code == 2 and "--scheduler 'foo'" in err and "threads" not in err


def test_rematch_from_the_command_line_equals_run_study(cli, tmp_path):
    # before: the re-matched evaluation (run_study's 'rematched', the honest measure of the
    # docs) had no CLI option; 'grid report' always showed '-' in its re-matched column
    common = ("--preset", "ILCE-7RM2", "--strips", "1", "--images-per-strip", "4", "--seed", "2")
    code, text, err = cli("grid", "evaluate", *common, "--spacing", "1000", "--rematch", "--json")
    assert code == 0, err
    got = json.loads(text)["rematched"]
    study = pg.calibration.run_study(
        "ILCE-7RM2", seed=2, strips=1, images_per_strip=4, spacing=1000, sweep=None
    )
    want = study["rematched"]
    assert got["mean_step_before"] == pytest.approx(want["mean_step_before"], rel=1e-9)
    assert got["mean_step_after"] == pytest.approx(want["mean_step_after"], rel=1e-9)
    code, text, err = cli("grid", "sweep", *common, "--spacings", "500,1000", "--rematch", "--json")
    assert code == 0, err
    sw = json.loads(text)
    assert sw["spacing_rematched"] in (500.0, 1000.0) and len(sw["step_rematched"][0]) == 2
    out = tmp_path / "r.html"
    code, _, err = cli(
        "grid", "report", *common, "--spacing", "1000", "--spacings", "500,1000", "--rematch",
        "-o", out,
    )  # fmt: skip
    assert code == 0, err
    row = _report_rows(out)["ILCE-7RM2"]
    assert row[1] == f"{want['mean_step_after']:.2f}"  # the 're-matched: after' column
    assert "mean step, re-matched (GSD)" in _report_rows(out)


def test_rematch_refusals(cli, adjusted_folder):
    code, _, err = cli("grid", "evaluate", adjusted_folder, "--rematch")
    assert code == 2 and "--rematch needs --preset" in err
    code, _, err = cli("grid", "sweep", adjusted_folder, "--rematch")
    assert code == 2 and "--rematch needs --preset" in err
    code, _, err = cli("grid", "evaluate", "--preset", "FC300S", "--rematch", "--in-adjustment")
    assert code == 2 and "--in-adjustment" in err


def test_grid_fit_of_a_bal_file_takes_the_image_size(cli, tmp_path):
    # before: a BAL block (no image size in the format) was fitted for the smallest even size
    # holding its observations (3892 x 2988 px here for 4000 x 3000 px images), with the
    # pixel origin there, silently, and --image-size was refused for a block
    sim, adj, bal = tmp_path / "sim", tmp_path / "adj", tmp_path / "block.bal"
    for args in (
        ("bundle", "simulate", sim, "--preset", "FC300S", "--strips", "1",
         "--images-per-strip", "3", "--free", "f,k1,k2", "--tie-points-per-image", "80"),
        ("bundle", "adjust", sim, "-o", adj),
        ("bundle", "convert", adj, bal, "--drop-extras"),
    ):  # fmt: skip
        code, _, err = cli(*args)
        assert code == 0, err
    out = tmp_path / "g.npz"
    code, _, err = cli("grid", "fit", bal, "--spacing", "1000", "-o", out, "--folds", "0")
    assert code == 0, err
    assert "a BAL file holds no image size" in err and "--image-size" in err
    code, _, err = cli(
        "grid", "fit", bal, "--spacing", "1000", "-o", out, "--folds", "0",
        "--image-size", "4000x3000",
    )  # fmt: skip
    assert code == 0, err
    assert "warning" not in err
    grids = pg.calibration.load_grids(out)
    block = pg.bundle.read_block(bal, image_size=(4000, 3000))
    want = pg.calibration.fit_residual_grids(block, 1000, folds=0)
    for k, g in want.items():
        assert grids[k].image_size == (4000, 3000)
        np.testing.assert_allclose(grids[k].nodes, g.nodes, rtol=0, atol=1e-12)


def test_grid_apply_on_a_folder_names_the_csv_to_give(cli, adjusted_folder, tmp_path):
    """OBSERVATIONS of 'grid apply' is a CSV: a block folder given instead is refused naming
    its observations.csv (before: 'cannot read (Is a directory)'), and the file so named
    gives the corrected observations; another folder is refused naming the columns."""
    grids = tmp_path / "grids.npz"
    code, _, err = cli("grid", "fit", adjusted_folder, "--spacing", "1000", "-o", grids)
    assert code == 0, err
    out = tmp_path / "corrected.csv"
    code, _, err = cli("grid", "apply", grids, adjusted_folder, "-o", out)
    assert code == 2 and not out.exists()
    named = str(adjusted_folder / "observations.csv")
    assert err.startswith("error: ") and named in err and "Is a directory" not in err
    code, _, err = cli("grid", "apply", grids, named, "-o", out)
    assert code == 0, err
    code, _, err = cli("grid", "apply", grids, tmp_path, "-o", out)  # no observations.csv
    assert code == 2 and "image_id, u, v" in err


def test_grids_of_a_block_not_adjusted_are_warned_about(cli, adjusted_folder, tmp_path):
    """'grid fit' and 'grid evaluate' of a block folder whose orientation is the start
    values (bundle simulate's block, before 'bundle adjust') warn, naming the residuals
    against their sigmas and the command that adjusts it; an adjusted block does not."""
    sim = pg.simulate.uav_block(
        "ILCE-7RM2", seed=2, strips=1, images_per_strip=4, tie_points_per_image=150
    )
    raw = tmp_path / "to-adjust"
    pg.bundle.write_csv_block(sim.block, raw)
    v = pg.bundle.reprojection_residuals(sim.block)
    assert np.sqrt(np.mean(v**2)) > 10 * 0.3  # start values: far above the 0.3 px noise
    for args in (
        ("grid", "fit", raw, "--spacing", "1000", "--folds", "0", "-o", tmp_path / "g.npz"),
        ("grid", "evaluate", raw, "--spacing", "1000"),
    ):
        code, _, err = cli(*args)
        assert code == 0, err
        assert "warning:" in err and "not adjusted" in err, err
        assert f"photogeom bundle adjust {raw}" in err
    for args in (
        ("grid", "fit", adjusted_folder, "--spacing", "1000", "--folds", "0",
         "-o", tmp_path / "h.npz"),
        ("grid", "evaluate", adjusted_folder, "--spacing", "1000"),
    ):  # fmt: skip
        code, _, err = cli(*args)
        assert code == 0, err
        assert "not adjusted" not in err, err


def test_a_folder_given_as_grids_file_names_where_grids_come_from(
    cli, adjusted_folder, tmp_path
):
    """GRIDS_FILE of 'grid apply' and 'grid correct-images' given a folder (the block, say)
    is refused naming the command that writes a grids file; load_grids says it in Python's
    words (save_grids)."""
    obs = adjusted_folder / "observations.csv"
    for args in (
        ("grid", "apply", adjusted_folder, obs, "-o", tmp_path / "c.csv"),
        ("grid", "correct-images", adjusted_folder, tmp_path, tmp_path / "out"),
    ):
        code, _, err = cli(*args)
        assert code == 2 and "a folder, not a grids file" in err, err
        assert "photogeom grid fit BLOCK -o grids.npz" in err and "save_grids" not in err
    with pytest.raises(pg.errors.FileFormatError, match="save_grids writes"):
        pg.calibration.load_grids(adjusted_folder)
    with pytest.raises(pg.errors.FileFormatError, match=r"no such grids file .*save_grids"):
        pg.calibration.load_grids(tmp_path / "none.npz")


def test_correct_images_names_a_file_that_differs_from_the_id_in_case_or_extension(
    cli, tmp_path
):
    # before: "no image file named DSC1.JPG (or DSC1.JPG.<ext>)" and, on another line, the
    # file among those "without a grid", with no word that the two were the same image
    import shutil

    grids_file, src = _small_grids_and_folder(tmp_path)
    grid = pg.calibration.load_grids(grids_file)["a"]
    ids = ["DSC1.JPG", "img_2", "a", "b.png"]
    pg.calibration.save_grids(grids_file, dict.fromkeys(ids, grid))
    shutil.move(src / "a.png", src / "DSC1.png")  # COLMAP's name, a copy in another format
    shutil.copy(src / "DSC1.png", src / "IMG_2.png")  # letter case
    shutil.copy(src / "DSC1.png", src / "a.png")  # matched by its stem: no hint
    shutil.copy(src / "DSC1.png", src / "B.PNG")  # the whole name in another case
    code, _, err = cli("grid", "correct-images", grids_file, src, tmp_path / "out")
    assert code == 1
    assert (
        "failed DSC1.JPG: no image file named DSC1.JPG (or DSC1.JPG.<ext>) in "
        f"{src} (file names are matched exactly, letter case included); DSC1.png has its "
        "name with another extension: rename it to DSC1.JPG.png"
    ) in err
    assert "IMG_2.png differs from it in letter case only: rename it to img_2.png" in err
    assert "B.PNG differs from it in letter case only: rename it to b.png" in err
    assert "failed a:" not in err and "a.png" not in err.replace("b.png", "")
    res = pg.calibration.correct_folder(
        src, tmp_path / "out2", pg.calibration.load_grids(grids_file), progress=False
    )
    assert list(res.written) == ["a"]
    assert "rename it to img_2.png" in res.failures["img_2"]


def test_pixel_options_written_with_their_unit_name_the_number_to_give(cli, tmp_path):
    # before: --spacing 100px was "Input should be a valid number, unable to parse string as
    # a number", --spacings 100px,200px "expected comma-separated numbers", and
    # --image-size 7952x5304px "expected WIDTHxHEIGHT": none said to leave out the unit
    res = tmp_path / "r.csv"
    rows = "".join(f"a,{u},{v},0.1,0.2\n" for u, v in [(1, 2), (50, 3), (4, 30), (40, 35)])
    res.write_text("image_id,u,v,rx,ry\n" + rows)
    out = tmp_path / "g.npz"
    base = ("grid", "fit", res, "-o", out)
    cases = [
        (
            (*base, "--image-size", "60x40", "--spacing", "100px"),
            "'100px' is not a number; --spacing is in px: give the number alone (--spacing 100)",
        ),
        (
            (*base, "--image-size", "7952 x 5304 px"),
            "--image-size is in px: give the numbers alone (--image-size 7952x5304)",
        ),
        (
            (*base, "--image-size", "60x40", "--sigma-constraint", "0.5 px"),
            "--sigma-constraint is in px: give the number alone (--sigma-constraint 0.5)",
        ),
        (
            ("grid", "evaluate", tmp_path, "--spacing", "100mm"),
            "'100mm' is not a number; --spacing is in px, not mm: give it in px, without a unit",
        ),
        (
            ("grid", "sweep", tmp_path, "--spacings", "100px, 200 px"),
            "--spacings is in px: give the numbers alone (--spacings 100,200)",
        ),
        (
            ("grid", "evaluate", tmp_path, "--sigma-constraint", "0.1px"),
            "--sigma-constraint is in px: give the number alone (--sigma-constraint 0.1)",
        ),
    ]
    for args, want in cases:
        code, _, err = cli(*args)
        assert code == 2 and want in " ".join(err.split()), (args, err)
    assert not out.exists()
    # a plain number still works
    code, _, err = cli(*base, "--image-size", "60x40", "--spacing", "20", "--folds", "0")
    assert code == 0, err
    assert pg.calibration.load_grids(out)["a"].layout.spacing == 20


def test_grids_of_another_camera_name_the_grids_file_as_the_fix(cli, adjusted_folder, tmp_path):
    # before: 'grid apply' advised "remove those rows" (most rows of a 7952 x 5304 px
    # camera lie outside a 4000 x 3000 px grid), 'grid evaluate --grids' said only "the grid
    # was fitted for a 4000 x 3000 px image, the block's camera is 7952 x 5304 px"
    block = pg.bundle.read_block(adjusted_folder)
    rng = np.random.default_rng(8)
    uv = rng.uniform([0, 0], [3999, 2999], (40, 2))
    other = pg.calibration.fit_grid(uv, np.full((40, 2), 0.2), (4000, 3000), 1000, folds=0)
    grids_file = tmp_path / "other.npz"
    pg.calibration.save_grids(grids_file, dict.fromkeys(block.image_ids.tolist(), other))
    obs = block.observations.uv
    code, _, err = cli(
        "grid", "apply", grids_file, adjusted_folder / "observations.csv", "-o", tmp_path / "c.csv"
    )
    assert code == 2
    assert (
        f"remove those rows, or, when {grids_file} holds the grids of another camera or block "
        f"(the rows reach u = {obs[:, 0].max():g}, v = {obs[:, 1].max():g} px), give the grids "
        "fitted for these observations (photogeom grid fit)"
    ) in " ".join(err.split())
    code, _, err = cli("grid", "evaluate", adjusted_folder, "--grids", grids_file)
    assert code == 2
    assert (
        "the grid was fitted for a 4000 x 3000 px image, the block's camera is 7952 x 5304 px: "
        "the grids are of another camera or block; give --grids the grids file of this BLOCK "
        "('photogeom grid fit BLOCK')"
    ) in " ".join(err.split())
    with pytest.raises(pg.InputError, match=r"fit the grids of this block \(fit_residual_grids"):
        pg.calibration.correct_observations(block, dict.fromkeys(block.image_ids.tolist(), other))


def test_grid_fit_table_prints_every_image_id_whole(cli, tmp_path):
    # before: in a pipe (110 columns) the image column was cut to "DSC00100.…", so the
    # ids a user gives --exclude or names the image files with could not be read
    long_id = "flight_2024-05-01_DJI_20240501123456_0001_V.JPG"
    ids = ["DSC00100.JPG", long_id]
    rng = np.random.default_rng(9)
    uv = rng.uniform([0, 0], [599, 399], (40, 2))
    res = tmp_path / "r.csv"
    res.write_text(
        "image_id,u,v,rx,ry\n"
        + "".join(f"{k},{u},{v},0.1,{u / 4000}\n" for k in ids for u, v in uv.tolist())
    )
    code, text, err = cli(
        "grid", "fit", res, "--image-size", "600x400", "--spacing", "200", "-o", tmp_path / "g.npz"
    )
    assert code == 0, err
    rows = [line for line in text.splitlines() if line.startswith("│")]
    assert [line.split("│")[1].strip() for line in rows] == ids
    assert all("…" not in line for line in text.splitlines())


def test_a_block_of_one_image_is_named_as_such(cli, adjusted_folder, tmp_path):
    # before: "302 tie point(s) are observed in fewer than two images and cannot be
    # intersected: ... (delete their rows from the block's files)", advice that deletes
    # every point of the block
    import shutil

    one = tmp_path / "one"
    shutil.copytree(adjusted_folder, one)
    first = str(pg.bundle.read_block(adjusted_folder).image_ids[0])
    for name in ("images.csv", "observations.csv"):
        lines = (one / name).read_text().splitlines(keepends=True)
        keep = ("id", "image_id", first)
        kept = [x for x in lines if x.startswith("#") or x.split(",")[0] in keep]
        (one / name).write_text("".join(kept))
    want = (
        f"the block has one image with observations ({first}): a bundle adjustment needs at "
        "least two images that observe the same points; add the block's other images and "
        "their observations"
    )
    for args in (("bundle", "adjust", one), ("grid", "evaluate", one, "--spacing", "1000")):
        code, _, err = cli(*args)
        assert code == 2 and err == f"error: {want}\n", (args, err)
    block = pg.bundle.read_block(one)
    with pytest.raises(pg.InputError, match="the block has one image with observations"):
        block.validate()


def test_a_sigma_column_of_a_residuals_csv_weighs_its_residuals_as_a_block_does(
    cli, adjusted_folder, tmp_path
):
    # before: the sigma column (px, as in a block's observations.csv) was ignored and every
    # residual had 1 px, so the CSV of a block's residuals gave other grids (sigma0 0.85
    # for 0.3 px residuals) than the block itself; --sigma-obs still sets them all
    block = pg.bundle.read_block(adjusted_folder)
    obs = block.observations
    tie = block.role[block.obs_point] == "tie"
    res = pg.bundle.reprojection_residuals(block)[tie]
    rows = zip(obs.image_ids[tie].tolist(), obs.uv[tie].tolist(), res.tolist(),
               obs.sigma[tie].tolist(), strict=True)  # fmt: skip
    path = tmp_path / "residuals.csv"
    path.write_text(
        "image_id,u,v,rx,ry,sigma\n"
        + "".join(f"{k},{u!r},{v!r},{a!r},{b!r},{s!r}\n" for k, (u, v), (a, b), s in rows)
    )
    w, h = (int(x) for x in block.image_sizes()[0])
    fits = {}
    for name, source, more in (
        ("block", adjusted_folder, ()),
        ("csv", path, ("--image-size", f"{w}x{h}", "--sigma-constraint", "scaled")),
        ("csv 1 px", path, ("--image-size", f"{w}x{h}", "--sigma-constraint", "scaled",
                            "--sigma-obs", "1")),
    ):  # fmt: skip
        out = tmp_path / f"{name}.npz"
        code, _, err = cli("grid", "fit", source, "--spacing", "1000", "-o", out, *more)
        assert code == 0, err
        fits[name] = pg.calibration.load_grids(out)
    assert np.allclose(np.unique(obs.sigma[tie]), 0.3)
    for k, g in fits["block"].items():
        c = fits["csv"][str(k)]
        np.testing.assert_allclose(c.nodes, g.nodes, atol=1e-9)
        assert c.sigma0 == pytest.approx(g.sigma0, rel=1e-9)
        assert c.rms_cv_after == pytest.approx(g.rms_cv_after, rel=1e-9)
        assert np.all(fits["csv 1 px"][str(k)].sigma_obs == 1.0)
        assert np.allclose(c.sigma_obs, 0.3)
    bad = tmp_path / "bad.csv"
    bad.write_text(path.read_text().replace(",0.3\n", ",0\n", 1))
    code, _, err = cli("grid", "fit", bad, "--image-size", f"{w}x{h}", "-o", tmp_path / "b.npz")
    assert code == 2 and "line 2, column sigma: 0 is not a positive number of pixels" in err


def test_grid_json_outputs_state_the_residual_convention_and_units(
    cli, adjusted_folder, tmp_path
):
    # before: the --json of grid fit, evaluate and sweep held bare numbers (px, GSD, CPU s,
    # fractions) without a word of their units or of the residuals' sign, which the printed
    # tables and the grids file state
    code, text, err = cli(
        "grid", "fit", adjusted_folder, "--spacing", "1000", "-o", tmp_path / "g.npz", "--json"
    )
    assert code == 0, err
    fit = json.loads(text)
    assert fit["residual_convention"] == "computed minus observed"
    for stats in fit["images"].values():
        numbers = {k for k, v in stats.items() if isinstance(v, float)}
        assert numbers <= set(fit["units"]), numbers - set(fit["units"])
    assert fit["units"]["rms_after"] == "px" and fit["units"]["reduction"] == "1"
    code, text, err = cli("grid", "evaluate", adjusted_folder, "--spacing", "1000", "--json")
    assert code == 0, err
    ev = json.loads(text)
    assert ev["residual_convention"] == "computed minus observed"
    floats = {k for k, v in ev["residuals"]["block"]["before"].items() if isinstance(v, float)}
    assert floats <= set(ev["units"])
    assert {k for k in ev if k.startswith(("mean_step", "steps_", "check_"))} <= set(ev["units"])
    assert ev["units"]["rms"] == "px" and ev["units"]["mean_step_after"] == "GSD"
    code, text, err = cli(
        "grid", "sweep", adjusted_folder, "--spacings", "500,1000", "--json"
    )
    assert code == 0, err
    sw = json.loads(text)
    assert sw["units"]["spacings"] == "px" and sw["units"]["step"] == "GSD"
    assert sw["units"]["time"] == "s (CPU)"


def test_correct_images_finds_ids_that_name_a_file_below_the_folder(cli, tmp_path):
    # COLMAP names an image by its path below the image folder (cam1/0001.jpg of a rig);
    # before: "no image file named cam1/a.png in images" though images/cam1/a.png was there
    import shutil

    import cv2

    grids_file, src = _small_grids_and_folder(tmp_path)
    grid = pg.calibration.load_grids(grids_file)["a"]
    for sub in ("cam1", "cam2"):
        (src / sub).mkdir()
    shutil.copy(src / "a.png", src / "cam1" / "a.png")
    img2 = np.full((40, 60), 200, np.uint8)
    cv2.imwrite(str(src / "cam2" / "a.png"), img2)  # the same name, another image
    (tmp_path / "outside.png").write_bytes((src / "a.png").read_bytes())
    ids = ["cam1/a.png", "cam2/a", "a", "../outside.png"]
    pg.calibration.save_grids(grids_file, dict.fromkeys(ids, grid))
    dst = tmp_path / "out"
    code, _, err = cli("grid", "correct-images", grids_file, src, dst)
    assert code == 1  # the id that leaves the folder is not read
    assert "failed ../outside.png: no image file named ../outside.png" in err
    assert sorted(str(p.relative_to(dst)) for p in dst.rglob("*.png")) == [
        "a.png", "cam1/a.png", "cam2/a.png"
    ]  # fmt: skip
    first = cv2.imread(str(src / "a.png"), cv2.IMREAD_UNCHANGED)
    want = pg.calibration.correct_image(first, grid)
    np.testing.assert_array_equal(cv2.imread(str(dst / "cam1" / "a.png"), -1), want)
    np.testing.assert_array_equal(
        cv2.imread(str(dst / "cam2" / "a.png"), -1), pg.calibration.correct_image(img2, grid)
    )


def test_an_id_with_its_folder_given_that_folder_names_the_one_above(cli, tmp_path):
    # a Bundler list's (or COLMAP's) id img/a.png with SRC_DIR the folder img itself: the
    # error said "a.png has its name with another extension: rename it to img/a.png.png"
    grids_file, src = _small_grids_and_folder(tmp_path)
    grid = pg.calibration.load_grids(grids_file)["a"]
    top = tmp_path / "project"
    (top / "img").mkdir(parents=True)
    (src / "a.png").rename(top / "img" / "a.png")
    pg.calibration.save_grids(grids_file, {"img/a.png": grid})
    code, _, err = cli("grid", "correct-images", grids_file, top / "img", tmp_path / "out")
    assert code == 1
    text = " ".join(err.split())
    assert "rename it" not in text and "a.png.png" not in text
    assert "the image id names its folder (img/)" in text
    assert f"give the folder that holds img/ ({top}) as the images' folder" in text
    code, _, err = cli("grid", "correct-images", grids_file, top, tmp_path / "out2")
    assert code == 0, err
    assert (tmp_path / "out2" / "img" / "a.png").is_file()


def test_overlap_in_per_cent_and_sigmas_with_their_unit_name_the_value_to_give(cli, tmp_path):
    # before: "Input should be a valid number, unable to parse string as a number" for
    # --overlap 60%, --sigma-obs 0.3px and --sigma-temporal 0.1px
    cases = [
        (("grid", "evaluate", tmp_path, "--overlap", "60%"),
         "'60%' is not a number; --overlap is a fraction: give 0.6 for 60 %"),
        (("grid", "sweep", tmp_path, "--overlap", "0.6x"),
         "'0.6x' is not a number; --overlap is a fraction, such as 0.6"),
        (("grid", "fit", tmp_path, "-o", tmp_path / "g.npz", "--sigma", "0.3 px"),
         "--sigma-obs is in px: give the number alone (--sigma-obs 0.3)"),
        (("grid", "report", tmp_path, "-o", tmp_path / "r.html", "--sigma-temporal", "0.1px"),
         "--sigma-temporal is in px: give the number alone (--sigma-temporal 0.1)"),
    ]  # fmt: skip
    for args, want in cases:
        code, _, err = cli(*args)
        assert code == 2 and want in " ".join(err.split()), (args, err)


def test_grid_fit_refuses_a_block_of_one_image_and_fits_its_residuals_csv(
    cli, adjusted_folder, tmp_path
):
    # before: grid fit of a block folder left with one image fitted its grid without a word,
    # though a block of one image cannot have been adjusted (bundle adjust refuses it); the
    # residuals of one image as a CSV are fitted as ever
    import shutil

    one = tmp_path / "one"
    shutil.copytree(adjusted_folder, one)
    block = pg.bundle.read_block(adjusted_folder)
    first = block.image_ids[0]
    for name in ("images.csv", "observations.csv"):
        lines = (one / name).read_text().splitlines(keepends=True)
        keep = ("id", "image_id", str(first))
        kept = [x for x in lines if x.startswith("#") or x.split(",")[0] in keep]
        (one / name).write_text("".join(kept))
    code, _, err = cli("grid", "fit", one, "--spacing", "1000", "--folds", "0",
                       "-o", tmp_path / "g.npz")  # fmt: skip
    assert code == 2 and not (tmp_path / "g.npz").exists()
    assert f"the block has one image with observations ({first}): a block of one image " \
        "cannot have been adjusted" in " ".join(err.split())
    assert "--exclude" in err and "image_id,u,v,rx,ry" in err
    # that image's residuals in the adjusted block, as a CSV: one grid, the block's grid
    v = pg.bundle.reprojection_residuals(block)
    rows = np.flatnonzero((block.obs_image == 0) & (block.role[block.obs_point] == "tie"))
    uv = block.observations.uv[rows]
    sigma = block.observations.sigma[rows]
    csv_path = tmp_path / "one.csv"
    csv_path.write_text("image_id,u,v,rx,ry,sigma\n" + "".join(
        f"{first},{a!r},{b!r},{c!r},{d!r},{s!r}\n"
        for (a, b), (c, d), s in zip(uv.tolist(), v[rows].tolist(), sigma.tolist())
    ))  # fmt: skip
    w, h = (int(x) for x in block.image_sizes()[0])
    code, _, err = cli("grid", "fit", csv_path, "--image-size", f"{w}x{h}", "--spacing", "1000",
                       "--folds", "0", "-o", tmp_path / "g.npz")  # fmt: skip
    assert code == 0, err
    got = pg.calibration.load_grids(tmp_path / "g.npz")
    assert [str(k) for k in got] == [str(first)]
    assert next(iter(got.values())).image_size == (w, h)


@pytest.mark.parametrize("existing", [False, True])
def test_correct_images_stopped_removes_the_empty_rig_folders_it_made(
    tmp_path, monkeypatch, existing
):
    # before: Ctrl-C or SIGTERM while the images ran left the empty cam1/, cam2/ (and their
    # parents) made for the rig's image ids in the output folder; the folders it did not
    # make stay, as does one holding a file
    from photogeom.calibration import images as images_module

    grids_file, src = _small_grids_and_folder(tmp_path)
    grid = pg.calibration.load_grids(grids_file)["a"]
    for sub in ("cam1", "rig/cam2"):
        (src / sub).mkdir(parents=True)
        (src / sub / "a.png").write_bytes((src / "a.png").read_bytes())
    grids = dict.fromkeys(["cam1/a.png", "rig/cam2/a.png", "a"], grid)
    dst = tmp_path / "out"
    if existing:  # the user's folder, with a sub-folder of its own and a file in rig/
        (dst / "mine").mkdir(parents=True)
        (dst / "rig").mkdir()
        (dst / "rig" / "notes.txt").write_text("x")

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(images_module, "_run_serial", stopped)
    with pytest.raises(KeyboardInterrupt):
        pg.calibration.correct_folder(src, dst, grids, progress=False)
    if existing:
        assert sorted(str(p.relative_to(dst)) for p in dst.rglob("*")) == [
            "mine", "rig", "rig/notes.txt"
        ]  # fmt: skip
    else:
        assert not dst.exists()
    # an image that fails leaves no empty folder either; the others are written
    monkeypatch.undo()
    (src / "rig" / "cam2" / "a.png").write_bytes(b"not an image")
    result = pg.calibration.correct_folder(src, dst, grids, progress=False)
    assert sorted(result.written) == ["a", "cam1/a.png"] and list(result.failures) == [
        "rig/cam2/a.png"
    ]
    assert not (dst / "rig" / "cam2").exists() and (dst / "cam1" / "a.png").is_file()
    assert (dst / "rig").is_dir() == existing


def test_correct_images_sigterm_runs_the_clean_up(cli, tmp_path, monkeypatch):
    # before: SIGTERM (a job scheduler's stop, kill PID) ended the process at once, without
    # the clean-up Ctrl-C runs: the empty cam1/ made for a rig's image id stayed
    import os
    import signal

    from photogeom.calibration import images as images_module

    grids_file, src = _small_grids_and_folder(tmp_path)
    grid = pg.calibration.load_grids(grids_file)["a"]
    (src / "cam1").mkdir()
    (src / "cam1" / "a.png").write_bytes((src / "a.png").read_bytes())
    pg.calibration.save_grids(grids_file, dict.fromkeys(["cam1/a.png", "a"], grid))
    dst = tmp_path / "out"

    def terminated(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        raise AssertionError("SIGTERM did not stop the run")

    def runner_kept(signum, frame):  # the handler of a command that installs none
        raise KeyboardInterrupt

    monkeypatch.setattr(images_module, "_run_serial", terminated)
    before = signal.signal(signal.SIGTERM, runner_kept)  # this test process is not killed
    try:
        code, _, _ = cli("grid", "correct-images", grids_file, src, dst)
        assert signal.getsignal(signal.SIGTERM) is runner_kept  # the former one restored
    finally:
        signal.signal(signal.SIGTERM, before)
    assert code == 143
    assert not dst.exists()


@pytest.mark.parametrize(("name", "fmt"), [("b.bal", "bal"), ("b.out", "bundler")])
def test_the_command_of_the_not_adjusted_warning_adjusts_the_block(cli, tmp_path, name, fmt):
    # the warning said "adjust it first ('photogeom bundle adjust b.bal -o adjusted/') and
    # give the adjusted folder": for a BAL or Bundler file (no control, no GNSS) that command
    # stopped at a datum defect, and with --datum free wrote a file named 'adjusted'
    import shlex

    sim = pg.simulate.uav_block("FC300S", seed=2, strips=2, images_per_strip=4)
    src = tmp_path / name
    pg.bundle.write_block(sim.block, src, fmt, drop_extras=True)
    size = ("--image-size", "4000x3000")
    code, _, err = cli("grid", "fit", src, "-o", tmp_path / "g.json", "--folds", "0",
                       "--no-std", *size)  # fmt: skip
    assert code == 0, err
    text = " ".join(err.split())
    command = re.search(r"adjust it first \('photogeom ([^']+)'\) and give (\S+)", text)
    assert command is not None, text
    args = shlex.split(command.group(1))
    assert "--datum" in args and args[args.index("-o") + 1] == command.group(2)
    code, _, err = cli(*args, *size)
    assert code == 0, err
    adjusted = Path(command.group(2))
    assert adjusted.is_file() and pg.bundle.detect_format(adjusted) == fmt
    code, _, err = cli("grid", "fit", adjusted, "-o", tmp_path / "g2.json", "--folds", "0",
                       "--no-std", *size)  # fmt: skip
    assert code == 0 and "not adjusted" not in err, err


def test_grids_of_a_bal_file_fitted_at_its_size_name_the_route_in_evaluate(cli, tmp_path):
    # grid fit adj.bal --image-size 4000x3000, then grid evaluate adj.bal --grids: evaluate
    # reads BAL at the smallest even size holding the observations without --image-size,
    # and the error said the grids "are of another camera or block; give --grids the grids
    # file of this BLOCK", which they were; it names --image-size, which evaluate now has
    sim = pg.simulate.uav_block("FC300S", seed=2, strips=2, images_per_strip=4)
    bal = tmp_path / "adj.bal"
    pg.bundle.write_block(sim.block, bal, "bal", drop_extras=True)
    block = pg.bundle.read_bal(bal, image_size=(4000, 3000))  # f, k1, k2 per image
    fit = pg.bundle_adjust(block, datum="free", snooping=False)
    pg.bundle.write_block(fit.block, bal, "bal")
    grids = tmp_path / "g.npz"
    code, _, err = cli("grid", "fit", bal, "--image-size", "4000x3000", "-o", grids,
                       "--folds", "0", "--no-std")  # fmt: skip
    assert code == 0, err
    code, _, err = cli("grid", "evaluate", bal, "--grids", grids)
    assert code != 0
    text = " ".join(err.split())
    assert "the grids are of another camera" not in text and "of this BLOCK" not in text
    assert f"{bal} is a BAL file, which holds no image size" in text
    assert "give the same --image-size WIDTHxHEIGHT here" in text, text
    code, _, err = cli("grid", "evaluate", bal, "--grids", grids, "--image-size", "4000x3000")
    assert code == 0, err
