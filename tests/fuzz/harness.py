"""Mutation fuzzing of photogeom's file readers: targets, seed corpus, mutations.

Shared by the bounded property test (``test_fuzz_readers.py``, run in CI) and the
long-running loop run by hand (``run_mutations.py``). A reader passes an input when it
returns normally or raises one of photogeom's own exceptions (:class:`PhotogeomError`);
any other exception is a finding. Seeds are built from the bundled data sets.
"""

from __future__ import annotations

import functools
import json
import random
import re
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import photogeom as pg
from photogeom.errors import PhotogeomError

# --- seed corpus -------------------------------------------------------------------------------


def _rpb_text(rpc: pg.RPC) -> str:
    """A DigitalGlobe .RPB rendering of ``rpc`` (the seed of the RPB reader)."""
    d = rpc.to_dict()
    names = {
        "lineOffset": "LINE_OFF", "sampOffset": "SAMP_OFF", "latOffset": "LAT_OFF",
        "longOffset": "LONG_OFF", "heightOffset": "HEIGHT_OFF", "lineScale": "LINE_SCALE",
        "sampScale": "SAMP_SCALE", "latScale": "LAT_SCALE", "longScale": "LONG_SCALE",
        "heightScale": "HEIGHT_SCALE",
    }  # fmt: skip
    lines = ['satId = "XXXX";', 'bandId = "P";', 'SpecId = "RPC00B";', "BEGIN_GROUP = IMAGE"]
    lines += ["\terrBias =   -1.00;", "\terrRand =    -1.00;"]
    lines += [f"\t{k} = {d[v]!r};" for k, v in names.items()]
    for k, v in (("lineNumCoef", "LINE_NUM_COEFF"), ("lineDenCoef", "LINE_DEN_COEFF"),
                 ("sampNumCoef", "SAMP_NUM_COEFF"), ("sampDenCoef", "SAMP_DEN_COEFF")):  # fmt: skip
        coeffs = ",\n".join(f"\t\t\t{c:+.15e}" for c in d[v])
        lines.append(f"\t{k} = (\n{coeffs});")
    lines += ["END_GROUP = IMAGE", "END;"]
    return "\n".join(lines) + "\n"


def _transform_seeds() -> list[bytes]:
    x = np.array([[0.0, 0, 0], [10, 0, 1], [0, 10, 2], [10, 10, 0], [5, 3, 7], [2, 8, 4]])
    X = pg.Similarity3D.from_helmert(
        10.0, -4.0, 2.0, 1.0, -2.0, 3.0, 5.0, convention="position_vector"
    ).apply(x)
    out = []
    x2 = np.vstack([x[:, :2], [[3, 3], [7, 1]]])
    X2 = np.vstack([X[:, :2], [[1, 2], [3, 1]]])
    for model, src, dst, kw in (
        ("similarity3d", x, X, {}),
        ("affine2d", x[:, :2], X[:, :2] * 1.01, {}),
        ("projective2d", x[:, :2], X[:, :2], {}),
        ("polynomial2d", x2, X2, {"order": 2}),
        ("affine3d", x, X * 1.01, {}),
    ):
        fit = pg.estimate_transform(model, src, dst, **kw)
        out.append(json.dumps({"model_parameters": fit.transform.to_dict()}, indent=2).encode())
    return out


def _camera_seeds() -> list[bytes]:
    io = pg.InteriorOrientation(152.14, x0=0.008, y0=-0.12, unit="mm")
    eo = pg.ExteriorOrientation(1114.0, 862.0, 1600.0, 0.01, 0.02, 0.3)
    both = {"interior": io.to_dict(), "exterior": eo.to_dict()}
    bare = {"f": 4000.0, "x0": 12.0, "y0": -3.0, "unit": "px",
            "distortion": {"k1": 0.01, "p1": 1e-4}}  # fmt: skip
    return [json.dumps(both, indent=2).encode(), json.dumps({"model_parameters": both}).encode(),
            json.dumps(bare).encode()]  # fmt: skip


def _metashape_seeds() -> list[bytes]:
    cal = pg.MetashapeCalibration(width=6000, height=4000, f=4000.0, cx=12.5, cy=-7.25,
                                  k1=-0.05, k2=0.01, p1=1e-4, b1=0.5)  # fmt: skip
    text = cal.to_xml_string()
    return [text.encode(), text.replace('encoding="UTF-8"', 'encoding="UTF-16"').encode("utf-16")]


def _camera_export_seeds() -> list[bytes]:
    """A Metashape camera export (File > Export > Export Cameras) of two sensors: the first
    with an initial and an adjusted calibration and the covariance, the second with an
    initial calibration without its own resolution; one image with its pose."""
    cal = pg.MetashapeCalibration(width=4000, height=3000, f=2312.5, cx=11.25, cy=-7.5,
                                  k1=-0.09, k2=0.07, p1=3e-4, b1=0.5, b2=-0.25)  # fmt: skip
    terms = "".join(f"<{n}>{getattr(cal, n)!r}</{n}>" for n in ("f", "cx", "cy", "b1", "b2", "k1",
                                                                 "k2", "p1"))  # fmt: skip
    text = (
        '<?xml version="1.0" encoding="UTF-8"?>\n<document version="2.0.0">\n'
        '<chunk label="Chunk 1" enabled="true">\n<sensors next_id="2">\n'
        '<sensor id="0" label="FC300S (3.61mm)" type="frame">\n'
        '<resolution width="4000" height="3000"/>\n'
        '<property name="pixel_width" value="0.00156"/>\n'
        '<bands><band label="Red"/><band label="Green"/><band label="Blue"/></bands>\n'
        '<calibration type="frame" class="initial"><resolution width="4000" height="3000"/>'
        "<f>2300</f></calibration>\n"
        '<calibration type="frame" class="adjusted">\n<resolution width="4000" height="3000"/>'
        f"\n{terms}\n</calibration>\n"
        "<covariance><params>f cx cy k1</params>"
        "<coeffs>4 0.1 0.2 1e-5 0.1 1 0.01 0 0.2 0.01 1.5 0 1e-5 0 0 1e-8</coeffs></covariance>\n"
        '</sensor>\n<sensor id="1" label="other" type="frame">\n'
        '<resolution width="6000" height="4000"/>\n'
        '<calibration type="frame" class="initial"><f>9000</f><k1>0.01</k1></calibration>\n'
        "</sensor>\n</sensors>\n<cameras next_id=\"1\">\n"
        '<camera id="0" sensor_id="0" label="IMG_1"><transform>1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1'
        "</transform></camera>\n</cameras>\n</chunk>\n</document>\n"
    )
    return [text.encode(), text.replace('encoding="UTF-8"', 'encoding="UTF-16"').encode("utf-16")]


def _calibration_seeds(fmt: str) -> list[bytes]:
    """A calibration written as ``fmt`` (``"opencv"`` YAML, ``"colmap"`` cameras.txt), with
    standard deviations and a covariance where the format has a place for them."""
    from photogeom.camera.calibration_files import calibration_text

    cal = pg.MetashapeCalibration(width=4000, height=3000, f=2238.75, cx=4.0, cy=-7.0,
                                  k1=-0.11, k2=0.1, k3=-0.035, p1=3e-4, p2=-2e-4)  # fmt: skip
    names = ("f", "cx", "cy", "k1")
    cov = (names, np.diag([0.25, 0.04, 0.04, 1e-8]))
    std = {"f": 0.5, "cx": 0.2, "cy": 0.2, "k1": 1e-4}
    return [calibration_text(cal, fmt, std=std, covariance=cov).encode()]


def _opencv_xml_seeds() -> list[bytes]:
    """An OpenCV ``cv2.FileStorage`` XML calibration, as OpenCV's calibration sample writes."""
    import tempfile

    import cv2

    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "camera.xml")
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", 4000)
        fs.write("image_height", 3000)
        fs.write("camera_matrix", np.array([[2238.0, 0, 2003.5], [0, 2238.0, 1492.5], [0, 0, 1]]))
        fs.write("distortion_coefficients", np.array([[-0.11, 0.1, -2e-4, 3e-4, -0.035]]))
        fs.release()
        return [Path(path).read_bytes()]


def _bundled(*names: str) -> list[bytes]:
    return [pg.datasets.path(n).read_bytes() for n in names]


# --- targets -----------------------------------------------------------------------------------


@dataclass
class Target:
    """One reader: ``read(path)`` on a file holding the input; its seeds; the file suffix."""

    name: str
    read: Callable[[Path], object]
    seeds: Callable[[], list[bytes]]
    suffix: str = ""


def _read_rpc(p: Path):
    return pg.read_rpc(p)


def _read_metashape(p: Path):
    return pg.read_metashape_xml(p)


def _read_camera_export(p: Path):
    import warnings

    from photogeom.camera.calibration_files import read_calibration_file

    with warnings.catch_warnings():  # the initial calibration of sensor 1 warns
        warnings.simplefilter("ignore")
        return read_calibration_file(p, sensor="0"), read_calibration_file(p, sensor="other")


def _read_transform_json(p: Path):
    from photogeom.cli.transform import load_transform_record

    return load_transform_record(p)[0]


def _read_camera_json(p: Path):
    from photogeom.cli.camera import camera_from_json

    return camera_from_json(p)


def _read_points(p: Path):
    from photogeom.io import read_points

    return read_points(p)


def _read_point_pairs(p: Path):
    from photogeom.io import read_point_pairs

    return read_point_pairs(p)


def _read_calibration(p: Path):
    return pg.read_calibration(p)


def _read_bal(p: Path):
    return pg.bundle.read_bal(p)


@functools.cache
def _colmap_binary_model() -> dict[str, bytes]:
    """The COLMAP binary model of the bundled BAL problem (photogeom's writer, the files
    pycolmap reads)."""
    from photogeom.bundle.io_colmap_bin import colmap_binaries

    return colmap_binaries(pg.bundle.read_bal(pg.datasets.path("dubrovnik-3-7")))


def _colmap_binary_target(name: str) -> tuple[Callable[[Path], object], Callable[[], list]]:
    """A reader of a binary model whose file ``name`` is the input, the other files the
    seed's; and the seed of ``name``."""

    def read(p: Path):
        model = p.parent / "model"
        model.mkdir(exist_ok=True)
        for other, data in _colmap_binary_model().items():
            (model / other).write_bytes(p.read_bytes() if other == name else data)
        return pg.bundle.read_colmap(model)

    return read, lambda: [_colmap_binary_model()[name]]


def _read_bundler(p: Path):
    return pg.bundle.read_bundler(p, image_size=(4000, 3000))


def _bundler_seeds() -> list[bytes]:
    """The bundled BAL problem as a Bundler file (its cameras are Bundler's)."""
    from photogeom.bundle.io_bundler import bundler_texts

    block = pg.bundle.read_bal(pg.datasets.path("dubrovnik-3-7"))
    return [bundler_texts(block)[0].encode("ascii")]


def _rpc_dir() -> Path:
    return pg.datasets.path("ikonos").parent


def _rpc_text_seeds() -> list[bytes]:
    names = ("rpc_IKONOS.txt", "skysat_l1a_RPC.TXT", "quickbird_gdal_autotest.rpc.txt")
    return [(_rpc_dir() / n).read_bytes() for n in names]


def _rpb_seeds() -> list[bytes]:
    return [_rpb_text(pg.read_rpc(pg.datasets.path("ikonos"))).encode()]


def _dimap_seeds() -> list[bytes]:
    return [(_rpc_dir() / "rpc_PLEIADES.xml").read_bytes()]


def _worldview_seeds() -> list[bytes]:
    return [(_rpc_dir() / "rpc_WV2.xml").read_bytes()]


def _points_seeds() -> list[bytes]:
    return _bundled("lidar_wang2014", "kraus_absolute_orientation", "lecture_fiducials")


def _pairs_seeds() -> list[bytes]:
    return _bundled("lecture_fiducials", "lidar_wang2014", "kraus_absolute_orientation")


TARGETS: dict[str, Target] = {
    t.name: t
    for t in (
        Target("rpc-text", _read_rpc, _rpc_text_seeds, ".txt"),
        Target("rpc-rpb", _read_rpc, _rpb_seeds, ".RPB"),
        Target("rpc-dimap", _read_rpc, _dimap_seeds, ".XML"),
        Target("rpc-worldview", _read_rpc, _worldview_seeds, ".XML"),
        Target("metashape-xml", _read_metashape, _metashape_seeds, ".xml"),
        Target("metashape-cameras", _read_camera_export, _camera_export_seeds, ".xml"),
        Target("transform-json", _read_transform_json, _transform_seeds, ".json"),
        Target("camera-json", _read_camera_json, _camera_seeds, ".json"),
        Target("points-csv", _read_points, _points_seeds, ".csv"),
        Target("point-pairs-csv", _read_point_pairs, _pairs_seeds, ".csv"),
        Target("opencv-yaml", _read_calibration, lambda: _calibration_seeds("opencv"), ".yaml"),
        Target("opencv-xml", _read_calibration, _opencv_xml_seeds, ".xml"),
        Target("colmap-cameras", _read_calibration, lambda: _calibration_seeds("colmap"), ".txt"),
        Target("bal", _read_bal, lambda: _bundled("dubrovnik-3-7"), ".txt"),
        *(
            Target(f"colmap-bin-{n.split('.')[0]}", *_colmap_binary_target(n), ".bin")
            for n in ("cameras.bin", "images.bin", "points3D.bin")
        ),
        Target("bundler", _read_bundler, _bundler_seeds, ".out"),
    )
}

#: Targets whose reader is the point CSV reader.
CSV_TARGETS = ("points-csv", "point-pairs-csv")


# --- mutations ---------------------------------------------------------------------------------

_TOKENS = [
    b"nan", b"NaN", b"inf", b"-inf", b"1e308", b"1e309", b"-1e308", b"1e-320", b"0", b"-0",
    b"1" * 5000, b"9" * 400, b" " * 5000, b"\t", b"\n" * 2000, b"\r\n", b"\x00", b"\xff\xfe",
    b"\xef\xbb\xbf", b'"', b"'", b",", b";", b":", b"=", b"(", b")", b"[" * 3000, b"{" * 3000,
    b"]", b"}", b"<", b">", b"</", b"<!DOCTYPE x [<!ENTITY a 'aaaa'>]>", b"&a;", b"&amp;",
    b"<![CDATA[", b"]]>", b"\xe9", b"\xc3\xa9", b"pixels", b"meters", b"#", b"-1", b"1e20",
    b"LINE_NUM_COEFF_01: 1", b"lineOffset = (", b"a = (\n" * 500, b"null", b"true", b"[]",
    b"{}", b'"model"', b'"f"', b"_" + b"1" * 3000, b"\\", b"\\u0000", b"\xed\xa0\x80",
]  # fmt: skip


_NUMBER = re.compile(rb"[-+]?[0-9][0-9.eE+-]{0,30}")


def _span(rng: random.Random, n: int) -> tuple[int, int]:
    a = rng.randrange(n + 1)
    b = min(n, a + rng.choice([1, 2, 4, 8, 32, 256, 4096]))
    return a, b


def mutate(data: bytes, rng: random.Random) -> bytes:
    """1-4 random edits of ``data``: byte flips, insertions of hostile tokens, deletions,
    repetitions of a slice (up to ~300 kB, to expose super-linear readers), line swaps,
    truncation, re-encoding."""
    buf = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        n = len(buf)
        op = rng.choice([0, 1, 1, 2, 3, 4, 4, 4, 5, 6, 7, 8])
        if op == 0 and n:  # flip bytes
            for _ in range(rng.randint(1, 8)):
                buf[rng.randrange(n)] = rng.randrange(256)
        elif op == 1:  # insert a token, possibly many times over
            i = rng.randrange(n + 1)
            buf[i:i] = (rng.choice(_TOKENS) * rng.choice([1, 1, 1, 10, 60]))[:300_000]
        elif op == 2 and n:  # delete a span
            a, b = _span(rng, n)
            del buf[a:b]
        elif op == 3 and n:  # repeat a span many times
            a, b = _span(rng, n)
            reps = rng.choice([2, 10, 100, 1000, 10000])
            chunk = bytes(buf[a:b]) * reps
            buf[b:b] = chunk[:300_000]
        elif op == 4 and n:  # replace a number by a hostile value
            m = _NUMBER.search(buf, rng.randrange(n))
            if m is None:
                m = _NUMBER.search(buf)
            if m is not None:
                buf[m.start() : m.end()] = rng.choice([*_TOKENS[:13], b"x", b"", b"pixels"])
        elif op == 5:  # swap two lines
            lines = bytes(buf).split(b"\n")
            if len(lines) > 2:
                a, b = rng.randrange(len(lines)), rng.randrange(len(lines))
                lines[a], lines[b] = lines[b], lines[a]
                buf = bytearray(b"\n".join(lines))
        elif op == 6 and n:  # truncate
            del buf[rng.randrange(n) :]
        elif op == 7:  # duplicate a line (conflicting keys)
            lines = bytes(buf).split(b"\n")
            k = rng.randrange(len(lines))
            lines.insert(rng.randrange(len(lines) + 1), lines[k])
            buf = bytearray(b"\n".join(lines))
        else:  # re-encode
            try:
                text = bytes(buf).decode("utf-8")
            except UnicodeDecodeError:
                continue
            enc = rng.choice(["utf-16", "utf-16-le", "latin-1", "utf-8-sig", "utf-32"])
            try:
                buf = bytearray(text.encode(enc))
            except UnicodeEncodeError:
                continue
    return bytes(buf)


# --- running one input -------------------------------------------------------------------------


@dataclass
class Outcome:
    ok: bool  # returned, or raised a PhotogeomError
    seconds: float
    error: BaseException | None


def run_one(target: Target, data: bytes, directory: Path) -> Outcome:
    """Write ``data`` to a file in ``directory`` and read it with ``target``."""
    path = directory / f"input{target.suffix}"
    path.write_bytes(data)
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            target.read(path)
    except PhotogeomError as exc:
        return Outcome(True, time.perf_counter() - t0, exc)
    except Exception as exc:  # the finding
        return Outcome(False, time.perf_counter() - t0, exc)
    return Outcome(True, time.perf_counter() - t0, None)
