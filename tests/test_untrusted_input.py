"""Hostile and malformed files: refused with photogeom's own error naming the problem, read
in time linear in their size, never silently accepted with wrong values.

Each case is a minimal file built from a bundled one. Inputs that made a super-linear reader
run for minutes are read here at full size: a regression shows as a test that hangs.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.cli.camera import camera_from_json
from photogeom.cli.transform import load_transform_record
from photogeom.errors import InputError, PhotogeomError
from photogeom.rpc import RPC, read_rpc

sys.path.insert(0, str(Path(__file__).parent / "fuzz"))
from harness import _rpb_text

IKONOS = pg.datasets.path("ikonos").read_text()
PLEIADES = pg.datasets.path("pleiades").read_text()
WV2 = pg.datasets.path("worldview2").read_text()


def load_transform(path):
    """The transformation of a parameter JSON, as the command line reads it."""
    return load_transform_record(path)[0]


def _file(tmp_path: Path, name: str, data: str | bytes) -> Path:
    p = tmp_path / name
    p.write_bytes(data.encode() if isinstance(data, str) else data)
    return p


def _refused(path: Path, *words: str, reader=read_rpc) -> str:
    with pytest.raises(PhotogeomError) as info:
        reader(path)
    msg = str(info.value)
    assert str(path) in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


# --- RPC KEY: value text -----------------------------------------------------------------------


def test_long_runs_of_spaces_inside_a_value_are_read_in_linear_time(tmp_path):
    # the old line pattern backtracked over the spaces: a 300 kB line took minutes
    text = IKONOS.replace("LINE_OFF: +005124.00 pixels", "LINE_OFF: 5124" + " " * 300_000 + "x")
    assert text != IKONOS
    _refused(_file(tmp_path, "a_RPC.TXT", text), "LINE_OFF", "'x'")
    spaced = IKONOS.replace("LINE_OFF: +005124.00 pixels", "LINE_OFF:" + " " * 300_000 + "5124")
    assert read_rpc(_file(tmp_path, "b_RPC.TXT", spaced)).line_off == 5124.0


def test_format_detection_is_linear_in_blank_lines(tmp_path):
    _refused(_file(tmp_path, "blank.txt", "x\n" + "\n" * 64_000 + "y"), "not a known RPC")
    text = "\n" * 60_000 + IKONOS
    assert read_rpc(_file(tmp_path, "lead.txt", text)).line_off == 5124.0


def test_numbered_keys_written_twice_or_with_thousands_of_digits(tmp_path):
    dup = IKONOS.replace("LINE_NUM_COEFF_1:", "LINE_NUM_COEFF_01: 0.5\nLINE_NUM_COEFF_1:")
    _refused(_file(tmp_path, "dup.txt", dup), "LINE_NUM_COEFF_01", "LINE_NUM_COEFF_1", "both")
    huge = IKONOS + "LINE_NUM_COEFF_" + "7" * 5000 + ": 1\n"
    _refused(_file(tmp_path, "huge.txt", huge), "exactly 20")
    both = IKONOS + "LINE_NUM_COEFF: " + " ".join(["0"] * 20) + "\n"
    _refused(_file(tmp_path, "both.txt", both), "both as a list and as numbered keys")
    again = IKONOS + "LINE_OFF: 1\n"
    _refused(_file(tmp_path, "again.txt", again), "LINE_OFF appears twice", "line")


def test_all_zero_denominator_and_nan_error_are_refused(tmp_path):
    lines = IKONOS.splitlines()
    zero = "\n".join(
        (ln.split(":")[0] + ": 0" if ln.startswith("LINE_DEN_COEFF_") else ln) for ln in lines
    )
    _refused(_file(tmp_path, "zero.txt", zero), "LINE_DEN_COEFF", "all 20 coefficients are zero")
    nan = IKONOS.replace("ERR_BIAS: 0003.31", "ERR_BIAS: nan")
    assert nan != IKONOS
    _refused(_file(tmp_path, "nan.txt", nan), "ERR_BIAS", "nan")
    with pytest.raises(InputError, match="ERR_RAND"):
        RPC(**{**_fields(read_rpc(pg.datasets.path("ikonos"))), "err_rand": float("inf")})


def _fields(rpc: RPC) -> dict:
    names = ("line_off samp_off lat_off long_off height_off line_scale samp_scale lat_scale "
             "long_scale height_scale line_num line_den samp_num samp_den").split()  # fmt: skip
    return {n: getattr(rpc, n) for n in names}


def test_oversized_text_file_is_refused_before_reading(tmp_path):
    _refused(_file(tmp_path, "big.txt", IKONOS + "#" * (1 << 20)), "too large")


def test_utf16_and_bom_text_files_read_as_utf8(tmp_path):
    ref = read_rpc(pg.datasets.path("ikonos"))
    for enc in ("utf-16", "utf-8-sig"):
        assert read_rpc(_file(tmp_path, f"{enc}.txt", IKONOS.encode(enc))).same_as(ref)


# --- RPB -------------------------------------------------------------------------------------


def test_rpb_duplicate_keys_and_second_block_are_refused(tmp_path):
    rpb = _rpb_text(read_rpc(pg.datasets.path("ikonos")))
    assert read_rpc(_file(tmp_path, "ok.RPB", rpb)).line_off == 5124.0
    dup = rpb.replace("\tsampOffset", "\tlineOffset = 1.0;\n\tsampOffset")
    _refused(_file(tmp_path, "dup.RPB", dup), "lineOffset given again", "line")
    body = rpb[rpb.index("BEGIN_GROUP") : rpb.index("END;")]
    _refused(_file(tmp_path, "two.RPB", rpb.replace("END;", body + "END;")), "given again")


def test_rpb_with_many_blank_or_open_lines_is_linear(tmp_path):
    # each pattern made the old assignment regex scan to the end of the file from every line
    _refused(_file(tmp_path, "open.RPB", "lineOffset = 1;\n" + "a = (\n" * 40_000),
             "missing key")  # fmt: skip
    _refused(_file(tmp_path, "blank.RPB", "lineOffset = 1;\n" + "\n" * 200_000 + "x"),
             "missing key")  # fmt: skip
    _refused(_file(tmp_path, "unclosed.RPB", "lineOffset = (1, 2\n" + "3,\n" * 20_000 + ";"),
             "closing")  # fmt: skip


# --- DIMAP and WorldView XML ---------------------------------------------------------------------


@pytest.mark.parametrize("value", ["abc", "nan", "inf", "pixels", "1e400", ""])
@pytest.mark.parametrize("tag", ["FIRST_COL", "LAST_COL", "LAST_ROW"])
def test_dimap_validity_domain_values_are_checked(tmp_path, tag, value):
    old = {"FIRST_COL": "<FIRST_COL>1</FIRST_COL>", "LAST_COL": "<LAST_COL>40000</LAST_COL>",
           "LAST_ROW": "<LAST_ROW>36176</LAST_ROW>"}[tag]  # fmt: skip
    text = PLEIADES.replace(old, f"<{tag}>{value}</{tag}>", 1)
    assert text != PLEIADES
    _refused(_file(tmp_path, "p.xml", text), tag)


def test_dimap_offset_given_as_a_unit_only_and_duplicates(tmp_path):
    start = PLEIADES.index("<SAMP_OFF>")
    end = PLEIADES.index("</SAMP_OFF>")
    _refused(_file(tmp_path, "u.xml", PLEIADES[:start] + "<SAMP_OFF>pixels" + PLEIADES[end:]),
             "SAMP_OFF")  # fmt: skip
    first = "<FIRST_COL>1</FIRST_COL>"
    dup = PLEIADES.replace(first, first + "<FIRST_COL>2</FIRST_COL>")
    _refused(_file(tmp_path, "d.xml", dup), "FIRST_COL", "2 times")
    i = PLEIADES.index("<SAMP_NUM_COEFF_3>")
    j = PLEIADES.index("</SAMP_NUM_COEFF_3>") + len("</SAMP_NUM_COEFF_3>")
    coef = PLEIADES[:j] + PLEIADES[i:j] + PLEIADES[j:]
    _refused(_file(tmp_path, "c.xml", coef), "SAMP_NUM_COEFF_3")


@pytest.mark.parametrize("value", ["many", "nan", "inf", "-3", "1e20", "2.5"])
def test_worldview_image_size_is_checked(tmp_path, value):
    text = WV2.replace("<NUMROWS>20289</NUMROWS>", f"<NUMROWS>{value}</NUMROWS>")
    _refused(_file(tmp_path, "w.xml", text), "NUMROWS")


def test_worldview_second_rpb_block_is_refused(tmp_path):
    i = WV2.index("<RPB>")
    j = WV2.index("</RPB>") + len("</RPB>")
    _refused(_file(tmp_path, "w.xml", WV2[:j] + WV2[i:j] + WV2[j:]), "RPB", "more than once")


@pytest.mark.parametrize("encoding", ["utf-16", "iso-8859-1"])
def test_xml_in_other_declared_encodings(tmp_path, encoding):
    text = WV2.replace('encoding="UTF-8"', f'encoding="{encoding.upper()}"', 1)
    if "encoding=" not in text.split("\n", 1)[0]:
        text = f'<?xml version="1.0" encoding="{encoding.upper()}"?>\n' + text.split("\n", 1)[1]
    text = text.replace("<SATID>", "<!-- caf\u00e9 --><SATID>")
    p = _file(tmp_path, "w.xml", text.encode(encoding))
    assert read_rpc(p).same_as(read_rpc(pg.datasets.path("worldview2")))


BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
<!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">]>
<Dimap_Document><Rational_Function_Model>&lol3;</Rational_Function_Model></Dimap_Document>
"""
XXE = """<?xml version="1.0"?>
<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>
<calibration><projection>&x;</projection></calibration>
"""


@pytest.mark.parametrize("doc", [BILLION_LAUGHS, XXE], ids=["billion-laughs", "xxe"])
def test_entity_attacks_are_refused(tmp_path, doc):
    _refused(_file(tmp_path, "e.xml", doc), "document type declaration")
    _refused(_file(tmp_path, "m.xml", doc), "document type declaration",
             reader=pg.read_metashape_xml)  # fmt: skip


# --- Metashape XML -----------------------------------------------------------------------------

CAL = pg.MetashapeCalibration(width=6000, height=4000, f=4000.0, cx=12.5, k1=-0.05, p1=1e-4)


@pytest.mark.parametrize("encoding", ["utf-16", "iso-8859-1", "utf-8"])
def test_metashape_xml_in_declared_encodings(tmp_path, encoding):
    text = CAL.to_xml_string().replace('encoding="UTF-8"', f'encoding="{encoding.upper()}"')
    text = text.replace("<calibration>", "<calibration><!-- Kalibrierung f\u00fcr K\u00e4mera -->")
    assert pg.read_metashape_xml(_file(tmp_path, "c.xml", text.encode(encoding))) == CAL


@pytest.mark.parametrize(("tag", "value", "words"), [
    ("f", "1e308", "focal length"), ("width", "1e20", "width"), ("height", "inf", "height"),
    ("cx", "1e300", "cx"), ("width", "0", "width"),
])  # fmt: skip
def test_metashape_implausible_values_are_refused(tmp_path, tag, value, words):
    text = CAL.to_xml_string()
    text = text.replace(f"<{tag}>{getattr(CAL, tag)}</{tag}>", f"<{tag}>{value}</{tag}>")
    assert f"<{tag}>{value}</{tag}>" in text
    _refused(_file(tmp_path, "c.xml", text), words, reader=pg.read_metashape_xml)


# --- JSON parameter files of the command line ---------------------------------------------------

SIM = {"model_parameters": {"model": "similarity2d", "a": 1.0, "b": 0.1, "c": 5.0, "d": -2.0}}
CAMERA = {
    "interior": {"f": 152.14, "x0": 0.008, "y0": -0.12, "unit": "mm"},
    "exterior": {"X0": 1.0, "Y0": 2.0, "Z0": 3.0, "omega": 0.0, "phi": 0.0, "kappa": 0.1},
}


@pytest.mark.parametrize(("text", "words"), [
    ("[" * 100_000 + "]" * 100_000, "nested"),
    ('{"model_parameters": {"model": "similarity2d", "a": 1' + "0" * 5000 + "}}", "digits"),
    ('{"model_parameters": {"model": "similarity2d", "a": NaN, "b": 0, "c": 0, "d": 0}}', "NaN"),
    ('{"model_parameters": {"model": "similarity2d", "a": 1, "b": 0, "c": 0}}', "'d'"),
    ('{"model_parameters": {"model": "affine3d", "linear": [[1, 0, 0], [0, 1], [0, 0, 1]],'
     ' "translation": [0, 0, 0]}}', "wrong type or shape"),
    ('{"model_parameters": {"model": "similarity2d", "a": "one", "b": 0, "c": 0, "d": 0}}', ""),
    ('{"model_parameters": {"model": "similarity2d", "a": {}, "b": 0, "c": 0, "d": 0}}', ""),
    ('{"model_parameters": {"model": ["similarity2d"]}}', ""),
    ("[1, 2]", "JSON object"),
    ('{"model_parameters": {"model": "polynomial2d", "order": 1e300, "coefficients": []}}', ""),
])  # fmt: skip
def test_transform_json_malformed(tmp_path, text, words):
    _refused(_file(tmp_path, "t.json", text), words, reader=load_transform)


def test_transform_json_encodings(tmp_path):
    text = json.dumps(SIM)
    ref = load_transform(_file(tmp_path, "u8.json", text))
    for enc in ("utf-16", "utf-8-sig", "utf-32"):
        t = load_transform(_file(tmp_path, f"{enc}.json", text.encode(enc)))
        np.testing.assert_array_equal(t.parameters, ref.parameters)
    latin = json.dumps({**SIM, "note": "\u00e9"}, ensure_ascii=False).encode("latin-1")
    _refused(_file(tmp_path, "l1.json", latin), "UTF-8", reader=load_transform)


@pytest.mark.parametrize(("data", "words"), [
    ({"interior": [152.14]}, "interior orientation"),
    ({"interior": {"x0": 0.0}}, "'f'"),
    ({"interior": {"f": "long"}}, ""),
    ({"interior": {"f": 1.0, "distortion": [1, 2]}}, "interior orientation"),
    ({"exterior": {"X0": 1}}, "missing"),
    ({"exterior": {**CAMERA["exterior"], "omega": [1, [2]]}}, ""),
    ({"exterior": {**CAMERA["exterior"], "angle_unit": 7}}, ""),
    ({"f": {"a": 1}}, ""),
])  # fmt: skip
def test_camera_json_malformed(tmp_path, data, words):
    _refused(_file(tmp_path, "c.json", json.dumps(data)), words, reader=camera_from_json)


def test_camera_json_reads(tmp_path):
    io, eo = camera_from_json(_file(tmp_path, "c.json", json.dumps(CAMERA)))
    assert io.f == 152.14 and eo.kappa == 0.1


def test_cli_reports_a_bad_json_in_one_line(cli, tmp_path):
    pts = _file(tmp_path, "p.csv", "id,x,y\na,1,2\n")
    bad = _file(tmp_path, "t.json", "{" * 10_000)
    code, _, err = cli("transform", "apply", bad, pts)
    assert code == 2 and err.startswith("error: ") and len(err.strip().splitlines()) == 1


# --- point CSV -----------------------------------------------------------------------------------


@pytest.mark.parametrize(("text", "words"), [
    ('id,x,y\n1,"2,3\n4,5,6\n7,8,9\n10,11,12\n', "quote"),
    ('id,x,y\n1,"2\n3",4\n', "quote"),
    ("id,x,y\n1," + "2" * 140_000 + ",3\n", "x"),
    ("id,x,y,weight\n1,2,3,heavy\n4,5,6,light\n7,8,9,x\n", "weight"),
    ("id,x,y,sigma\n1,2,3,1e308\n4,5,6,1\n7,8,9,1\n", "sigma"),  # weight 1e-616 = 0
])  # fmt: skip
def test_point_csv_hostile_fields_are_refused(tmp_path, text, words):
    from photogeom.io import read_points

    _refused(_file(tmp_path, "p.csv", text), words, reader=read_points)


def test_point_csv_header_with_many_columns_is_linear(tmp_path):
    from photogeom.io import read_points

    header = ",".join(f"c{i}" for i in range(12_000))
    _refused(_file(tmp_path, "p.csv", "id,x,y," + header + "\n1,2,3\n"), "", reader=read_points)


_JSON_TEXT = st.text(alphabet='[]{}"\\ax\u00e9', max_size=6)
_JSON = st.recursive(
    st.none() | st.floats(allow_nan=False) | _JSON_TEXT,
    lambda kids: st.lists(kids, max_size=3) | st.dictionaries(_JSON_TEXT, kids, max_size=3),
    max_leaves=20,
)


def _depth(obj) -> int:
    if isinstance(obj, list):
        return 1 + max((_depth(v) for v in obj), default=0)
    if isinstance(obj, dict):
        return 1 + max((_depth(v) for v in obj.values()), default=0)
    return 0


@settings(max_examples=100)
@given(obj=_JSON, ascii_only=st.booleans())
def test_json_depth_scan_matches_the_parsed_structure(obj, ascii_only):
    """The pre-parse depth scan (strings with brackets, quotes, backslashes skipped) agrees
    with the depth of the parsed document."""
    from photogeom.io import jsonfile

    data = json.dumps(obj, ensure_ascii=ascii_only).encode()
    limit = jsonfile.MAX_DEPTH
    jsonfile.MAX_DEPTH = 0  # scan every document, however shallow
    try:
        got = jsonfile._max_depth(data)
    finally:
        jsonfile.MAX_DEPTH = limit
    assert got == _depth(obj)


def test_metashape_xml_size_limit_holds_on_every_path(tmp_path, cli):
    # the README's limit of a Metashape XML (1 MiB) held for read_metashape_xml only:
    # read_calibration (--calibration, --camera, camera convert) read a 2 MiB one, under
    # the 16 MiB of a JSON
    from photogeom.camera.calibration_files import read_calibration_file
    from photogeom.camera.metashape import MAX_XML_BYTES
    from photogeom.errors import FileFormatError

    cal = pg.MetashapeCalibration(width=6000, height=4000, f=4000.0, cx=12.5, cy=-7.25, k1=-0.05)
    text = cal.to_xml_string()
    at = text.index("<calibration")

    def padded(n: int) -> Path:
        path = tmp_path / f"cal-{n}.xml"
        path.write_text(text[:at] + f"<!--{'x' * n}-->\n" + text[at:], encoding="utf-8")
        return path

    small, big = padded(1000), padded(MAX_XML_BYTES)
    assert pg.read_calibration(small) == pg.read_metashape_xml(small) == cal
    for read in (pg.read_metashape_xml, pg.read_calibration, read_calibration_file):
        with pytest.raises(FileFormatError, match=f"more than {MAX_XML_BYTES} bytes"):
            read(big)
    code, _, err = cli("camera", "convert", big, tmp_path / "out.yaml")
    assert code == 2 and f"more than {MAX_XML_BYTES} bytes" in err
    assert not (tmp_path / "out.yaml").exists()
