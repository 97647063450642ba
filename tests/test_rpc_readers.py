"""RPC readers and writer: every format, round trips, and bad files."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import FileFormatError
from photogeom.rpc import RPC, read_rpc, write_rpc
from photogeom.rpc.writer import format_rpc

NAMES = ("quickbird", "ikonos", "skysat", "pleiades", "worldview2")


def text_of(name: str) -> str:
    return pg.datasets.path(name).read_text()


@pytest.mark.parametrize("name", NAMES)
def test_every_bundled_file_reads(name):
    rpc = RPC.from_file(pg.datasets.path(name))
    assert rpc.coefficients.shape == (4, 20)
    assert np.all(np.isfinite(rpc.coefficients))
    assert rpc.line_den[0] == 1.0 and rpc.samp_den[0] == 1.0


def test_values_read_from_the_ikonos_file():
    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    assert (rpc.line_off, rpc.samp_off, rpc.height_off) == (5124.0, 6334.0, 28.0)
    assert (rpc.lat_off, rpc.long_off) == (-34.903, -56.1722)
    assert rpc.line_num[0] == -1.490910093701323e-03
    assert rpc.samp_den[19] == 1.929684859424581e-09
    assert (rpc.err_bias, rpc.err_rand) == (3.31, 0.5)
    assert "numbered" in rpc.source


def test_values_read_from_the_quickbird_lists():
    rpc = RPC.from_file(pg.datasets.path("quickbird"))
    assert (rpc.line_off, rpc.samp_off, rpc.lat_scale) == (16201.0, 15184.0, 0.09)
    assert rpc.line_num[2] == -1.010407e00
    assert rpc.samp_num[19] == -1.716541e-07
    assert "lists" in rpc.source


def test_dimap_pixel_origin_is_converted_from_one_based():
    text = text_of("pleiades")
    rpc = RPC.from_file(pg.datasets.path("pleiades"))
    file_samp_off = float(re.search(r"<SAMP_OFF>([^<]+)<", text).group(1))
    file_line_off = float(re.search(r"<LINE_OFF>([^<]+)<", text).group(1))
    assert rpc.samp_off == file_samp_off - 1 and rpc.line_off == file_line_off - 1
    assert rpc.image_size == (40000, 36176)
    assert any("first pixel centre" in n for n in rpc.notes)
    # projection uses the Inverse_Model block (ground -> image), not the Direct_Model
    m = re.search(r"<Inverse_Model>.*?<SAMP_NUM_COEFF_2>([^<]+)<", text, re.S)
    assert rpc.samp_num[1] == float(m.group(1))
    assert rpc.direct is not None


def test_dimap_direct_model_approximates_the_exact_localisation():
    rpc = RPC.from_file(pg.datasets.path("pleiades"))
    c0, c1, r0, r1 = rpc.image_bounds
    C, R = np.meshgrid(np.linspace(c0, c1, 9), np.linspace(r0, r1, 9))
    lon_d, lat_d = rpc.localize_direct(C, R, 70.0)
    lon, lat = rpc.localize(C, R, 70.0)
    # the vendor's image-to-ground fit is good to a small fraction of a pixel (0.5 m GSD)
    gsd_deg = 0.5 / 111_000
    assert np.max(np.abs(lon_d - lon)) < 0.1 * gsd_deg
    assert np.max(np.abs(lat_d - lat)) < 0.1 * gsd_deg
    with pytest.raises(pg.InputError, match="no image-to-ground"):
        RPC.from_file(pg.datasets.path("ikonos")).localize_direct(0.0, 0.0, 0.0)


def test_dimap_v3_blocks_and_zero_based_validity_domain(tmp_path):
    # DIMAP v3 (Pleiades Neo) names: GroundtoImage_Values / ImagetoGround_Values with LON_/LAT_
    # keys, and a validity domain that may start at 0
    text = text_of("pleiades")
    direct = re.search(r"<Direct_Model>.*?</Direct_Model>", text, re.S).group(0)
    v3_direct = direct.replace("Direct_Model", "ImagetoGround_Values")
    for a, b in (("SAMP_NUM", "LON_NUM"), ("SAMP_DEN", "LON_DEN"), ("LINE_NUM", "LAT_NUM"),
                 ("LINE_DEN", "LAT_DEN")):  # fmt: skip
        v3_direct = v3_direct.replace(a, b)
    v3 = text.replace(direct, v3_direct).replace("Inverse_Model", "GroundtoImage_Values")
    v3 = v3.replace("Direct_Model_Validity_Domain", "ImagetoGround_Validity_Domain")
    v3 = v3.replace("<FIRST_ROW>1</FIRST_ROW>", "<FIRST_ROW>0</FIRST_ROW>")
    v3 = v3.replace("<FIRST_COL>1</FIRST_COL>", "<FIRST_COL>0</FIRST_COL>")
    rpc = read_rpc(_write(tmp_path, "RPC_PNEO.XML", v3))
    v2 = RPC.from_file(pg.datasets.path("pleiades"))
    assert rpc.source == "DIMAP v3 XML"
    assert rpc.samp_off == v2.samp_off + 1 and rpc.line_off == v2.line_off + 1
    np.testing.assert_array_equal(rpc.coefficients, v2.coefficients)
    np.testing.assert_array_equal(rpc.direct.coefficients, v2.direct.coefficients)


def test_worldview_xml_block_and_image_size():
    rpc = RPC.from_file(pg.datasets.path("worldview2"))
    assert (rpc.line_off, rpc.samp_off, rpc.height_scale) == (10108.0, 14104.0, 501.0)
    assert rpc.line_num[2] == -9.314605e-01
    assert rpc.image_size == (28244, 20289)
    assert rpc.err_bias == 26.68


def _rpb_text(rpc: RPC) -> str:
    def coef(name, values):
        body = ",\n".join(f"\t\t\t{float(v)!r}" for v in values)
        return f"\t{name} = (\n{body});\n"

    return (
        'satId = "WV02";\nbandId = "P";\nSpecId = "RPC00B";\nBEGIN_GROUP = IMAGE\n'
        f"\terrBias = {rpc.err_bias!r};\n\terrRand = {rpc.err_rand!r};\n"
        f"\tlineOffset = {rpc.line_off!r};\n\tsampOffset = {rpc.samp_off!r};\n"
        f"\tlatOffset = {rpc.lat_off!r};\n\tlongOffset = {rpc.long_off!r};\n"
        f"\theightOffset = {rpc.height_off!r};\n\tlineScale = {rpc.line_scale!r};\n"
        f"\tsampScale = {rpc.samp_scale!r};\n\tlatScale = {rpc.lat_scale!r};\n"
        f"\tlongScale = {rpc.long_scale!r};\n\theightScale = {rpc.height_scale!r};\n"
        + coef("lineNumCoef", rpc.line_num)
        + coef("lineDenCoef", rpc.line_den)
        + coef("sampNumCoef", rpc.samp_num)
        + coef("sampDenCoef", rpc.samp_den)
        + "END_GROUP = IMAGE\nEND;\n"
    )


def test_rpb_file(tmp_path):
    ref = RPC.from_file(pg.datasets.path("worldview2"))
    p = tmp_path / "image.RPB"
    p.write_text(_rpb_text(ref))
    rpc = RPC.from_file(p)
    assert rpc.source == "RPB"
    assert rpc.same_as(ref)
    assert (rpc.err_bias, rpc.err_rand) == (ref.err_bias, ref.err_rand)
    # truncated: the last coefficient block is gone
    text = _rpb_text(ref)
    q = tmp_path / "cut.RPB"
    q.write_text(text[: text.index("\tsampDenCoef")])
    with pytest.raises(FileFormatError, match="missing key sampDenCoef"):
        RPC.from_file(q)
    # a missing scalar is named in the RPB spelling
    q.write_text(text.replace("\theightScale = 501.0;\n", ""))
    with pytest.raises(FileFormatError, match="heightScale"):
        RPC.from_file(q)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("style", ["ikonos", "lists"])
def test_writer_round_trip_is_exact(name, style, tmp_path):
    rpc = RPC.from_file(pg.datasets.path(name))
    out = write_rpc(rpc, tmp_path / f"{name}_RPC.TXT", style=style)
    back = read_rpc(out)
    assert back.same_as(rpc)  # exact equality of offsets, scales, coefficients
    assert (back.err_bias, back.err_rand) == (rpc.err_bias, rpc.err_rand)
    assert (back.direct is None) == (rpc.direct is None)
    # and the written text reads back into the same text
    assert format_rpc(back, style) == out.read_text()


def test_writer_folds_a_shift_and_refuses_cross_terms(tmp_path):
    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    shifted = rpc.with_correction([[0.0, 0.0, 4.5], [0.0, 0.0, -2.25]])
    back = read_rpc(write_rpc(shifted, tmp_path / "s.txt"))
    assert back.samp_off == rpc.samp_off + 4.5 and back.line_off == rpc.line_off - 2.25
    g = (-56.17, -34.9, 20.0)
    assert np.allclose(back.project(*g), shifted.project(*g), atol=1e-9)
    with pytest.raises(pg.InputError, match=r"[Rr]e-fit"):
        write_rpc(rpc.with_correction([[0.0, 1e-4, 0.0], [0.0, 0.0, 0.0]]), tmp_path / "x.txt")
    with pytest.raises(pg.InputError, match="style"):
        write_rpc(rpc, tmp_path / "y.txt", style="nitf")


def test_written_ikonos_text_is_readable_by_the_numbered_key_convention(tmp_path):
    rpc = RPC.from_file(pg.datasets.path("quickbird"))
    text = format_rpc(rpc, "ikonos")
    assert "LINE_OFF: 16201.0 pixels" in text
    assert "SAMP_DEN_COEFF_20: 5.142751e-08" in text
    assert len(re.findall(r"^LINE_NUM_COEFF_\d+:", text, re.M)) == 20


def test_mapping_with_strings_as_in_gdal_metadata():
    rpc = RPC.from_file(pg.datasets.path("skysat"))
    md = rpc.to_gdal_metadata()
    assert isinstance(md["LINE_NUM_COEFF"], str) and len(md["LINE_NUM_COEFF"].split()) == 20
    assert RPC.from_dict(md).same_as(rpc)
    lower = {k.lower(): v for k, v in md.items()}
    assert RPC.from_dict(lower).same_as(rpc)


# --- bad files --------------------------------------------------------------------------------


def _write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_unknown_and_empty_files(tmp_path):
    with pytest.raises(FileFormatError, match="not a known RPC file format"):
        read_rpc(_write(tmp_path, "a.txt", "hello world\nthis is not an RPC\n"))
    with pytest.raises(FileFormatError, match="empty"):
        read_rpc(_write(tmp_path, "b.txt", "\n  \n"))
    with pytest.raises(FileFormatError, match="no such file"):
        read_rpc(tmp_path / "missing.txt")
    with pytest.raises(FileFormatError, match="without a known RPC block"):
        read_rpc(_write(tmp_path, "c.xml", "<?xml version='1.0'?><root><a>1</a></root>"))
    with pytest.raises(FileFormatError, match="not well-formed XML"):
        read_rpc(_write(tmp_path, "d.xml", text_of("worldview2")[:3000]))


def test_truncated_ikonos_file_names_the_missing_key(tmp_path):
    lines = text_of("ikonos").splitlines()
    cut = "\n".join(
        lines[: lines.index(next(x for x in lines if x.startswith("SAMP_DEN_COEFF_18")))]
    )
    with pytest.raises(FileFormatError, match=r"SAMP_DEN_COEFF_18, SAMP_DEN_COEFF_19") as e:
        read_rpc(_write(tmp_path, "cut_RPC.TXT", cut))
    assert "truncated" in str(e.value)
    no_scale = "\n".join(x for x in lines if not x.startswith("LAT_SCALE"))
    with pytest.raises(FileFormatError, match="missing key LAT_SCALE"):
        read_rpc(_write(tmp_path, "noscale_RPC.TXT", no_scale))


def test_wrong_coefficient_counts(tmp_path):
    text = text_of("quickbird")
    line = next(x for x in text.splitlines() if x.startswith("SAMP_NUM_COEFF"))
    short = text.replace(line, line.rsplit(" ", 1)[0])
    with pytest.raises(FileFormatError, match="SAMP_NUM_COEFF has 19 coefficient"):
        read_rpc(_write(tmp_path, "short.txt", short))
    extra = text_of("ikonos") + "LINE_NUM_COEFF_21: 1.0\n"
    with pytest.raises(FileFormatError, match="LINE_NUM_COEFF_21"):
        read_rpc(_write(tmp_path, "extra_RPC.TXT", extra))
    xml = text_of("pleiades")
    xml_cut = re.sub(r"<LINE_DEN_COEFF_20>[^<]*</LINE_DEN_COEFF_20>", "", xml, count=2)
    with pytest.raises(FileFormatError, match="LINE_DEN_COEFF_20"):
        read_rpc(_write(tmp_path, "p.xml", xml_cut))
    wv = text_of("worldview2")
    wv_short = re.sub(r"(<SAMPNUMCOEF>)\S+ ", r"\1", wv)
    with pytest.raises(FileFormatError, match="SAMP_NUM_COEFF has 19"):
        read_rpc(_write(tmp_path, "w.xml", wv_short))


def test_keys_without_values_and_bad_numbers(tmp_path):
    text = text_of("ikonos")
    with pytest.raises(FileFormatError, match="HEIGHT_OFF has no value"):
        read_rpc(_write(tmp_path, "h_RPC.TXT", re.sub(r"HEIGHT_OFF:.*", "HEIGHT_OFF:", text)))
    with pytest.raises(FileFormatError, match="HEIGHT_OFF has no value"):
        read_rpc(
            _write(tmp_path, "h2_RPC.TXT", re.sub(r"HEIGHT_OFF:.*", "HEIGHT_OFF: meters", text))
        )
    with pytest.raises(FileFormatError, match="not a number"):
        read_rpc(_write(tmp_path, "n_RPC.TXT", text.replace("+0028.000", "2x8")))
    with pytest.raises(FileFormatError, match="LINE_NUM_COEFF_3 has no value"):
        read_rpc(
            _write(tmp_path, "c_RPC.TXT", re.sub(r"LINE_NUM_COEFF_3:.*", "LINE_NUM_COEFF_3:", text))
        )
    with pytest.raises(FileFormatError, match="appears twice"):
        read_rpc(_write(tmp_path, "d_RPC.TXT", text + "LINE_OFF: 1\n"))
    wv = text_of("worldview2")
    with pytest.raises(FileFormatError, match="HEIGHTOFFSET"):
        read_rpc(_write(tmp_path, "w.xml", re.sub(r"<HEIGHTOFFSET>[^<]*<", "<HEIGHTOFFSET><", wv)))
    xml = text_of("pleiades")
    with pytest.raises(FileFormatError, match="HEIGHT_OFF"):
        read_rpc(_write(tmp_path, "p.xml", re.sub(r"<HEIGHT_OFF>[^<]*</HEIGHT_OFF>", "", xml)))


def test_incomplete_image_to_ground_polynomials(tmp_path):
    text = format_rpc(RPC.from_file(pg.datasets.path("pleiades")), "lists")
    cut = "\n".join(x for x in text.splitlines() if not x.startswith("LAT_DEN_COEFF"))
    with pytest.raises(FileFormatError, match="missing LAT_DEN_COEFF"):
        read_rpc(_write(tmp_path, "x.txt", cut))


# --- GeoTIFF through rasterio (optional extra) ------------------------------------------------


def test_geotiff_rpc_tags(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    ref = RPC.from_file(pg.datasets.path("ikonos"))
    p = tmp_path / "image.tif"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        with rasterio.open(
            p, "w", driver="GTiff", width=64, height=48, count=1, dtype="uint8"
        ) as dst:
            dst.write(np.zeros((1, 48, 64), dtype="uint8"))
            dst.update_tags(ns="RPC", **ref.to_gdal_metadata())
    rpc = RPC.from_file(p)
    assert rpc.image_size == (64, 48)
    assert "raster" in rpc.source
    # GDAL stores the coefficients with about 15 significant digits
    assert rpc.same_as(ref, rtol=1e-13)
    q = tmp_path / "plain.tif"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        with rasterio.open(q, "w", driver="GTiff", width=8, height=8, count=1, dtype="uint8") as d:
            d.write(np.zeros((1, 8, 8), dtype="uint8"))
    with pytest.raises(FileFormatError, match="no RPC metadata"):
        RPC.from_file(q)


def test_pixel_convention_matches_gdal_rpc_transformer_plus_half_pixel():
    rasterio = pytest.importorskip("rasterio")
    from rasterio.rpc import RPC as GdalRPC
    from rasterio.transform import RPCTransformer

    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    tr = RPCTransformer(GdalRPC.from_gdal(rpc.to_gdal_metadata()))
    lon = np.array([-56.17, -56.2, -56.12])
    lat = np.array([-34.9, -34.92, -34.88])
    h = np.array([30.0, 50.0, 0.0])
    rows, cols = tr.rowcol(lon, lat, h, op=lambda x: x)
    col, row = rpc.project(lon, lat, h)
    # GDAL's RPC transformer puts (0, 0) at the top-left corner of the first pixel
    np.testing.assert_allclose(np.asarray(cols), col + 0.5, atol=1e-6)
    np.testing.assert_allclose(np.asarray(rows), row + 0.5, atol=1e-6)
    assert rasterio.__gdal_version__


def test_dictionary_round_trip_keeps_direct_model_and_correction():
    rpc = RPC.from_file(pg.datasets.path("pleiades"))
    assert RPC.from_dict(rpc.to_dict()).same_as(rpc)
    corrected = rpc.with_correction([[1e-4, 2e-4, 3.0], [0.0, 1e-4, -1.0]])
    d = corrected.to_dict()
    assert d["IMAGE_CORRECTION"] == corrected.correction.tolist()
    assert RPC.from_dict(d).same_as(corrected)
    # GDAL metadata has no place for a correction with cross terms
    with pytest.raises(pg.InputError, match="cross terms"):
        corrected.to_gdal_metadata()
    assert "LON_NUM_COEFF" not in rpc.to_gdal_metadata()
