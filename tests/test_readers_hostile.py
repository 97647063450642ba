"""Readers under hostile input: work linear in the input, named refusals."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from photogeom.bundle import io_csv, read_csv_block
from photogeom.errors import FileFormatError

_BLOCK = {
    "cameras.csv": "camera,width,height,f\nc,100,80,90\n",
    "images.csv": "id,camera,X0,Y0,Z0,omega_deg,phi_deg,kappa_deg\n1,c,0,0,10,0,0,0\n",
    "points.csv": "id,role,X,Y,Z,sX,sY,sZ\n1,tie,0,0,0,,,\n",
    "observations.csv": "image_id,point_id,u,v,sigma\n1,1,49.5,39.5,0.5\n",
}


def _block_folder(tmp_path, **files):
    for name, text in {**_BLOCK, **files}.items():
        (tmp_path / name).write_text(text)
    return tmp_path


class _CountingName(str):
    """A column name that counts the equality tests made with it."""

    tests = 0

    def __eq__(self, other):
        type(self).tests += 1
        return str.__eq__(self, other)

    __hash__ = str.__hash__


def test_block_csv_header_checked_in_linear_work(tmp_path, monkeypatch):
    """The repeated-column check compared every header name with every other (n^2 tests:
    a 40,000-column header took 55 s); now each name is hashed once."""
    real = io_csv._split_line

    def split(line, sep, path, number):
        cells, quoted = real(line, sep, path, number)
        return [_CountingName(c) for c in cells], quoted

    monkeypatch.setattr(io_csv, "_split_line", split)
    n = 3000
    header = ",".join(f"c{k}" for k in range(n)) + ",c7"
    folder = _block_folder(tmp_path, **{"cameras.csv": header + "\n"})
    _CountingName.tests = 0
    with pytest.raises(FileFormatError, match=r"column\(s\) c7 appear more than once"):
        read_csv_block(folder)
    assert _CountingName.tests < 10 * n  # was n^2 = 9,000,000


def test_block_csv_messages_list_a_bounded_number_of_columns(tmp_path):
    header = ",".join(f"c{k}" for k in range(5000))
    folder = _block_folder(tmp_path, **{"cameras.csv": header + "\n"})
    with pytest.raises(FileFormatError, match="column 'camera' not found") as err:
        read_csv_block(folder)
    msg = str(err.value)
    assert "c19, ... (4980 more)" in msg
    assert len(msg) < 400 + len(str(tmp_path))


# ------------------------------------------------------------------ grids files (JSON)


def _grids_json(tmp_path) -> bytes:
    import numpy as np

    from photogeom.calibration import GridLayout, ResidualGrid, save_grids

    layout = GridLayout(90, 60, 30)
    counts = np.full(layout.shape, 4)
    g = ResidualGrid(layout=layout, nodes=np.zeros((*layout.shape, 2)), sigma0=1.0,
                     redundancy=5, sigma_obs=np.ones(3), sigma_constraint=0.1,
                     support=counts >= 3, counts=counts, rms_before=1.0, rms_after=0.5,
                     outliers=np.zeros(4, bool))  # fmt: skip
    return save_grids(tmp_path / "good.json", {"a": g}).read_bytes()


@pytest.mark.parametrize(
    "content, match",
    [
        (b"[" * 100_000 + b"]" * 100_000, "nested more than 64 levels"),
        (b'{"format": ' + b"[" * 5000 + b"]" * 5000 + b"}", "nested more than 64 levels"),
        (b'{"format": 1' + b"0" * 5000 + b"}", "integer of 5001 digits"),
        (b"\xff\xfe\x00\xd8", "not UTF-8 text"),
    ],
)
def test_grids_json_hostile_content_is_named(tmp_path, content, match):
    """Deep nesting ended in a RecursionError traceback, a huge integer in Python's
    ValueError about int digits (text mentioning sys.set_int_max_str_digits)."""
    from photogeom.calibration import load_grids

    p = tmp_path / "g.json"
    p.write_bytes(content)
    with pytest.raises(FileFormatError, match=match) as err:
        load_grids(p)
    assert "grid fit" in str(err.value)


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16", "utf-16-le", "utf-32"])
def test_grids_json_in_other_unicode_encodings_is_read(tmp_path, encoding):
    """A byte-order mark or UTF-16 (a file re-saved by an editor) was refused as 'not a
    grids JSON file (Unexpected UTF-8 BOM ...)'; JSON allows them and they are now read."""
    from photogeom.calibration import load_grids

    text = _grids_json(tmp_path).decode("utf-8")
    p = tmp_path / "g.json"
    p.write_bytes(text.encode(encoding))
    assert list(load_grids(p)) == ["a"]


def test_grids_npz_with_deeply_nested_meta_is_named(tmp_path):
    import numpy as np

    from photogeom.calibration import load_grids

    p = tmp_path / "g.npz"
    np.savez(p, meta=np.array("[" * 100_000 + "]" * 100_000))
    with pytest.raises(FileFormatError, match="nested more than 64 levels"):
        load_grids(p)


# ------------------------------------------------------------------ bundle result records


@pytest.mark.parametrize(
    "content, match",
    [
        (b"\xff\xfe" + '{"a": 1}'.encode("utf-16-le"), "not a bundle adjustment result"),
        (b"[" * 100_000 + b"]" * 100_000, "nested more than 64 levels"),
        (b'{"format": 1' + b"0" * 5000 + b"}", "integer of 5001 digits"),
        (b'{"format": "photogeom-bundle-result", "version": 1}', "no converged, message"),
        (
            b'{"format": "photogeom-bundle-result", "version": 1, "images": 3}',
            "images is not a list",
        ),
        (b"\xe9t\xe9", "not UTF-8 text"),
    ],
)
def test_bundle_result_hostile_content_is_named(tmp_path, content, match):
    """UTF-16 and Latin-1 ended in UnicodeDecodeError, deep nesting in RecursionError, a huge
    integer in ValueError, a record without its entries in KeyError (in 'bundle report')."""
    from photogeom.report.bundle import read_bundle_result

    p = tmp_path / "r.json"
    p.write_bytes(content)
    with pytest.raises(FileFormatError, match=match):
        read_bundle_result(p)


def test_bundle_result_that_is_a_folder_is_named(tmp_path):
    from photogeom.report.bundle import read_bundle_result

    (tmp_path / "r.json").mkdir()
    with pytest.raises(FileFormatError, match="cannot read"):
        read_bundle_result(tmp_path / "r.json")


def test_bundle_report_cli_names_a_damaged_record(tmp_path, cli):
    """A record with its top-level entries but damaged below them ended in a KeyError
    traceback of 'photogeom bundle report'."""
    import json

    record = {"format": "photogeom-bundle-result", "version": 1, "converged": True,
              "message": "m", "unit": "m", "angle_unit": "deg", "redundancy": 3, "sigma0": 1.0,
              "sigma0_prior": 1.0, "rmse_px": 1.0, "gsd": None, "block": {}, "chi2": {},
              "calibration": {}, "calibration_std": {}, "calibration_correlation": {},
              "images": []}  # fmt: skip
    p = tmp_path / "r.json"
    p.write_text(json.dumps(record))
    code, out, err = cli("bundle", "report", p, "-o", tmp_path / "r.html")
    assert code != 0
    assert "without the entry 'n_images'" in err
    assert "Traceback" not in out + err


# ------------------------------------------------------------------ grid fit: residual CSVs


@pytest.mark.parametrize(
    "sep, words", [("\t", "separated by tabs"), (";", "separated by semicolons")]
)
def test_grid_csv_in_another_dialect_names_the_separator(tmp_path, cli, sep, words):
    """A tab- or semicolon-separated residuals file was refused as "no column 'image_id'
    (columns: image_id	u	v	rx	ry)", the tabs printed raw and no fix named."""
    p = tmp_path / "r.csv"
    p.write_text(sep.join(["image_id", "u", "v", "rx", "ry"]) + "\n" + sep.join("a1234") + "\n")
    code, _out, err = cli("grid", "fit", p, "--image-size", "100x100", "-o", tmp_path / "g.json")
    assert code == 2
    assert words in err and "replace the separators with commas" in err
    if sep == "\t":
        assert "image_id\\tu\\tv" in err


@pytest.mark.parametrize("line", ["a,1,2,0.1," + "9" * 200_000, 'b,1,2,"0.1,0.2'])
def test_grid_csv_field_over_the_limit_is_not_called_an_encoding_problem(tmp_path, cli, line):
    """A field over the csv module's 128 KiB limit (or a quote left open, which swallows
    the lines after it) was reported as 'not a UTF-8 CSV file (field larger than field
    limit (131072))', without a line."""
    p = tmp_path / "r.csv"
    rows = ["image_id,u,v,rx,ry", "a,1,2,0.1,0.2", line] + ["c,1,2,0.1,0.2"] * 20_000
    p.write_text("\n".join(rows) + "\n")
    code, _out, err = cli("grid", "fit", p, "--image-size", "100x100", "-o", tmp_path / "g.json")
    assert code == 2
    assert "UTF-8" not in err
    assert f"{p}, line 3: cannot split the line into fields" in err


# ------------------------------------------------------------------ UTF-16 / UTF-32 text

_WIDE = ["utf-16", "utf-16-le", "utf-16-be", "utf-32", "utf-32-le"]


@pytest.mark.parametrize("encoding", _WIDE)
def test_point_csv_in_utf16_is_refused_with_the_fix(tmp_path, encoding):
    """A point CSV saved as 'Unicode text' was refused as 'it looks like a binary file, not
    a CSV text file': true of neither the file nor the fix."""
    from photogeom.io import read_points

    p = tmp_path / "p.csv"
    p.write_bytes("id,X,Y,Z\na,1,2,3\n".encode(encoding))
    with pytest.raises(FileFormatError, match=r"text .*; photogeom reads CSV files as UTF-8: save"):
        read_points(p)


@pytest.mark.parametrize("encoding", _WIDE)
def test_block_files_in_utf16_are_read(tmp_path, encoding):
    """BAL and CSV block files (COLMAP: the same reader) in UTF-16/32 were refused as 'it is
    a binary file, not text'; they are text, and are now read as such."""
    import photogeom as pg
    from photogeom.bundle import read_bal, write_bal, write_csv_block

    block = read_bal(pg.datasets.path("dubrovnik-3-7"))
    bal = write_bal(block, tmp_path / "b.txt")
    bal.write_bytes(bal.read_text().encode(encoding))
    assert read_bal(bal).n_observations == block.n_observations
    folder = tmp_path / "csv"
    write_csv_block(block, folder)
    obs = folder / "observations.csv"
    obs.write_bytes(obs.read_text().encode(encoding))
    assert read_csv_block(folder).n_observations == block.n_observations


def test_binary_files_are_still_refused_as_binary(tmp_path):
    from photogeom.bundle import read_bal
    from photogeom.io import read_points

    p = tmp_path / "x.bin"
    p.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(FileFormatError, match="binary file"):
        read_bal(p)
    with pytest.raises(FileFormatError, match="binary file"):
        read_points(p)


# ------------------------------------------------------------------ images: PNG metadata


def test_png_icc_chunk_is_not_inflated_whole():
    """The iCCP chunk of a PNG was decompressed whole without a bound: a 1 MB file whose
    profile inflates to 1 GiB (a zlib bomb) took 2 GB of memory in 'grid correct-images'.
    Only the profile's header (its colour space) is needed, and only it is decompressed."""
    import struct
    import zlib

    from photogeom.calibration import images

    header = bytes(16) + b"GRAY" + bytes(108)
    profile = header + bytes(64 << 20)  # 64 MiB
    data = b"icc\x00\x00" + zlib.compress(profile, 9)
    chunk = struct.pack(">I", len(data)) + b"iCCP" + data + b"\x00\x00\x00\x00"
    head = images._png_icc(chunk)
    assert head is not None and len(head) <= images._ICC_HEAD
    assert head[16:20] == b"GRAY"
    assert images._icc_other(head, b"RGB ")
    assert images._png_icc(b"\x00\x00\x00\x05iCCPnoNUL\x00\x00\x00\x00") is None


# ------------------------------------------------------------------ property: named errors only

_TOKENS = st.sampled_from(
    ["0", "1", "2", "-1", "3.5", "1e308", "1e400", "nan", "inf", "", " ", "\t", "\n", "\r\n",
     ",", ";", '"', "#", "\ufeff", "\x00", "é", "1,5", "99999999999999999999999", "x" * 300]
)  # fmt: skip


@settings(max_examples=80, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])  # fmt: skip
@given(tokens=st.lists(_TOKENS, max_size=60), head=st.sampled_from(["", "3 7 19\n", "1 1 1\n"]))
def test_bal_reader_raises_only_named_errors(tmp_path, tokens, head):
    from photogeom.bundle import read_bal

    p = tmp_path / "b.txt"
    p.write_bytes((head + " ".join(tokens)).encode("utf-8"))
    try:
        read_bal(p)
    except FileFormatError:
        pass


@settings(max_examples=80, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])  # fmt: skip
@given(
    cells=st.lists(st.lists(_TOKENS, min_size=1, max_size=6), max_size=6),
    which=st.sampled_from(sorted(_BLOCK)),
    encoding=st.sampled_from(["utf-8", "utf-16"]),
)
def test_csv_block_reader_raises_only_named_errors(tmp_path, cells, which, encoding):
    header = _BLOCK[which].splitlines()[0]
    text = header + "\n" + "\n".join(",".join(row) for row in cells) + "\n"
    folder = _block_folder(tmp_path)
    (folder / which).write_bytes(text.encode(encoding, errors="surrogatepass"))
    try:
        read_csv_block(folder)
    except FileFormatError:
        pass


def test_grids_npz_with_a_huge_array_header_is_named_before_allocating(tmp_path):
    """A 1 kB NPZ whose nodes header announced 10^10 values ended in MemoryError ('Unable
    to allocate 74.5 GiB'): numpy allocates the array before reading it."""
    import io
    import json
    import zipfile

    import numpy as np
    from numpy.lib import format as npy

    from photogeom.calibration import gridfile, load_grids

    p = tmp_path / "g.npz"
    meta = {"format": gridfile.FORMAT, "version": gridfile.VERSION, "images": []}
    with zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED) as z:
        b = io.BytesIO()
        np.save(b, np.array(json.dumps(meta)))
        z.writestr("meta.npy", b.getvalue())
        h = io.BytesIO()
        npy.write_array_header_1_0(h, {"descr": "<f8", "fortran_order": False,
                                       "shape": (10**10,)})  # fmt: skip
        z.writestr("nodes_0.npy", h.getvalue() + bytes(64))
    with pytest.raises(FileFormatError, match=r"nodes_0 announces shape \(10000000000,\)"):
        load_grids(p)


def test_grids_npz_of_highly_compressible_arrays_still_reads(tmp_path):
    import numpy as np

    from photogeom.calibration import GridLayout, ResidualGrid, load_grids, save_grids

    layout = GridLayout(3000, 2000, 10)
    counts = np.zeros(layout.shape, dtype=np.int64)
    g = ResidualGrid(layout=layout, nodes=np.zeros((*layout.shape, 2)), sigma0=1.0,
                     redundancy=5, sigma_obs=np.ones(200_000), sigma_constraint=0.1,
                     support=counts >= 3, counts=counts, rms_before=1.0, rms_after=0.5,
                     outliers=np.zeros(2_000_000, bool))  # fmt: skip
    back = load_grids(save_grids(tmp_path / "g.npz", {"a": g}))
    assert back["a"].outliers.size == 2_000_000


def test_image_with_a_width_over_opencv_limit_is_a_named_error(tmp_path):
    """A TIFF whose ImageWidth tag is damaged (2^31 - 1) ended in cv2.error ('Assertion
    failed ... CV_IO_MAX_IMAGE_WIDTH') from correct_image_file, documented to raise
    FileFormatError for corrupt files."""
    import struct

    import numpy as np
    from PIL import Image

    from photogeom.calibration import GridLayout, ResidualGrid
    from photogeom.calibration.images import correct_image_file

    src = tmp_path / "a.tif"
    Image.fromarray(np.zeros((24, 32, 3), np.uint8)).save(src)
    data = bytearray(src.read_bytes())
    (ifd,) = struct.unpack_from("<I", data, 4)
    (count,) = struct.unpack_from("<H", data, ifd)
    for k in range(count):
        at = ifd + 2 + 12 * k
        (tag,) = struct.unpack_from("<H", data, at)
        if tag == 256:  # ImageWidth
            struct.pack_into("<HHII", data, at, 256, 4, 1, 2**31 - 1)
    src.write_bytes(bytes(data))
    layout = GridLayout(32, 24, 8)
    counts = np.zeros(layout.shape, np.int64)
    grid = ResidualGrid(layout=layout, nodes=np.zeros((*layout.shape, 2)), sigma0=1.0,
                        redundancy=1, sigma_obs=np.ones(1), sigma_constraint=0.1,
                        support=counts >= 3, counts=counts, rms_before=1.0, rms_after=1.0,
                        outliers=np.zeros(1, bool))  # fmt: skip
    with pytest.raises(FileFormatError, match=r"not a readable image .*OpenCV refuses it"):
        correct_image_file(src, tmp_path / "b.tif", grid)


def test_png_chunk_longer_than_the_file_is_refused_before_decoding(tmp_path, monkeypatch):
    """A 2 kB PNG whose image data chunk claimed 1.3 GB: OpenCV allocated it before
    reading and needed 2.3 s and 1.2 GB of memory to find the file unreadable."""
    import struct

    import cv2
    import numpy as np

    from photogeom.calibration import images

    _ok, png = cv2.imencode(".png", np.zeros((24, 32, 3), np.uint8))
    data = bytearray(png.tobytes())
    idat = data.index(b"IDAT") - 4
    struct.pack_into(">I", data, idat, 1_309_280_547)
    src = tmp_path / "a.png"
    src.write_bytes(bytes(data))

    def no_decoding(*_a):
        raise AssertionError("decoded")

    monkeypatch.setattr(images, "_decode_quietly", no_decoding)
    with pytest.raises(FileFormatError, match="PNG chunk 'IDAT' at byte 33 announces 1309280547"):
        images._read(src)


@pytest.mark.parametrize("reader", ["read_bal", "read_bundler"])
def test_a_long_token_that_is_not_a_number_is_named_in_linear_work(tmp_path, reader):
    # the pattern that finds the bad token matched a run of n digits in n^2 / 2 steps (a
    # 20 000-digit token took 25 s to name, 400 000 digits would take hours); now linear.
    # Run in a child process so that a regression fails on the timeout, not by hanging.
    import subprocess
    import sys

    token = "9" * 400_000 + "x"
    path = tmp_path / "f.txt"
    # counts that leave room for the token (64 characters a value)
    head = "# Bundle file v0.3\n1 300\n" if reader == "read_bundler" else "1 1 500\n"
    path.write_text(f"{head}0 0 {token} 1\n")
    code = (
        "import sys, photogeom as pg\n"
        "from photogeom.errors import FileFormatError\n"
        "try:\n"
        f"    pg.bundle.{reader}(sys.argv[1], image_size=(10, 10))\n"
        "except FileFormatError as exc:\n"
        "    print(str(exc)[-40:])\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().endswith("99x' is not a number")
