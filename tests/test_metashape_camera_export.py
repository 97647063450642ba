"""A Metashape camera export (File > Export > Export Cameras, root ``<document>``) read as a
calibration: one sensor's adjusted calibration (else its initial one, with a warning) and
the ``<covariance>`` beside it, equal to the same calibration written as a calibration XML
by photogeom's writer. Before, every reader refused it ("root element is <document>,
expected <calibration>")."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.camera.calibration_files import (
    METASHAPE_ORDER,
    calibration_text,
    metashape_covariance_from_xml,
    read_calibration_file,
    read_metashape_covariance,
)
from photogeom.camera.metashape import MetashapeXMLWarning
from photogeom.camera.metashape_export import sensor_calibration
from photogeom.xmlsafe import parse_xml

# As Metashape 2.x writes it (the sensor's resolution, properties, bands, the initial and the
# adjusted calibration, the covariance beside them, the cameras with their poses); sensor 1
# as Metashape 1.x wrote a sensor not yet aligned: an initial calibration, without its own
# <resolution>.
EXPORT = """<?xml version="1.0" encoding="UTF-8"?>
<document version="2.0.0">
  <chunk label="Chunk 1" enabled="true">
    <sensors next_id="2">
      <sensor id="0" label="FC300S (3.61mm)" type="frame">
        <resolution width="4000" height="3000"/>
        <property name="pixel_width" value="0.00156"/>
        <property name="pixel_height" value="0.00156"/>
        <property name="focal_length" value="3.61"/>
        <property name="layer_index" value="0"/>
        <bands>
          <band label="Red"/>
          <band label="Green"/>
          <band label="Blue"/>
        </bands>
        <data_type>uint8</data_type>
        <calibration type="frame" class="initial">
          <resolution width="4000" height="3000"/>
          <f>2314.1</f>
        </calibration>
        <calibration type="frame" class="adjusted">
          <resolution width="4000" height="3000"/>
          <f>2312.5</f>
          <cx>11.25</cx>
          <cy>-7.5</cy>
          <b1>0.5</b1>
          <b2>-0.25</b2>
          <k1>-0.0925</k1>
          <k2>0.0703</k2>
          <k3>-0.0125</k3>
          <k4>0.002</k4>
          <p1>0.0003</p1>
          <p2>-0.0001</p2>
        </calibration>
        <covariance>
          <params>f cx cy b1 k1</params>
          <coeffs>4 0.1 0.2 0.3 1e-05 0.1 1 0.01 0 0 0.2 0.01 1.5 0 0
            0.3 0 0 0.25 0 1e-05 0 0 0 1e-08</coeffs>
        </covariance>
        <meta>
          <property name="Exif/Make" value="DJI"/>
        </meta>
      </sensor>
      <sensor id="1" label="FC6310 (8.8mm)" type="frame">
        <resolution width="5472" height="3648"/>
        <calibration type="frame" class="initial">
          <f>3648.5</f>
          <cx>-3.5</cx>
          <k1>0.011</k1>
        </calibration>
      </sensor>
    </sensors>
    <components next_id="1" active_id="0">
      <component id="0" label="Component 1"/>
    </components>
    <cameras next_id="2" next_group_id="0">
      <camera id="0" sensor_id="0" component_id="0" label="DJI_0001">
        <transform>1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1</transform>
      </camera>
      <camera id="1" sensor_id="1" component_id="0" label="DJI_0002"/>
    </cameras>
  </chunk>
</document>
"""
CAL0 = pg.MetashapeCalibration(
    4000,
    3000,
    2312.5,
    cx=11.25,
    cy=-7.5,
    b1=0.5,
    b2=-0.25,
    k1=-0.0925,
    k2=0.0703,
    k3=-0.0125,
    k4=0.002,
    p1=0.0003,
    p2=-0.0001,
)
NAMES0 = ("f", "cx", "cy", "b1", "k1")
COV0 = np.array(
    [
        [4, 0.1, 0.2, 0.3, 1e-5],
        [0.1, 1, 0.01, 0, 0],
        [0.2, 0.01, 1.5, 0, 0],
        [0.3, 0, 0, 0.25, 0],
        [1e-5, 0, 0, 0, 1e-8],
    ]
)
CAL1 = pg.MetashapeCalibration(5472, 3648, 3648.5, cx=-3.5, k1=0.011)


def _write(tmp_path, text: str, name: str = "cameras.xml"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_sensor_equals_its_calibration_xml_written_by_photogeom(tmp_path):
    export = _write(tmp_path, EXPORT)
    # the same calibration and covariance as a calibration XML, by photogeom's writer
    xml = _write(tmp_path, calibration_text(CAL0, "metashape", covariance=(NAMES0, COV0)), "c.xml")
    for sensor in (0, "0", "FC300S (3.61mm)"):
        cal, std, cov = read_calibration_file(export, sensor=sensor)
        cal_x, std_x, cov_x = read_calibration_file(xml)
        assert cal == cal_x == CAL0
        assert cov[0] == cov_x[0] == NAMES0
        np.testing.assert_array_equal(cov[1], cov_x[1])
        np.testing.assert_array_equal(cov[1], COV0)
        assert std == std_x
        assert std["f"] == 2.0 and std["b1"] == 0.5
    assert pg.read_metashape_xml(export, sensor=0, strict=True) == CAL0
    names, C = read_metashape_covariance(export, sensor="FC300S (3.61mm)")
    assert names == NAMES0
    np.testing.assert_array_equal(C, COV0)


def test_the_initial_calibration_is_read_when_there_is_no_adjusted_one(tmp_path):
    export = _write(tmp_path, EXPORT)
    with pytest.warns(MetashapeXMLWarning, match=r'id="1".* no adjusted calibration: its initial'):
        cal, std, cov = read_calibration_file(export, sensor="FC6310 (8.8mm)")
    # the size from the sensor's <resolution> (the calibration has none)
    assert cal == CAL1 and std == {} and cov is None
    with pytest.warns(MetashapeXMLWarning):
        read = sensor_calibration(parse_xml(EXPORT, "cameras.xml"), "cameras.xml", 1)
    assert (read.sensor_id, read.label, read.calibration_class) == (
        "1",
        "FC6310 (8.8mm)",
        "initial",
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the adjusted calibration: no warning
        read = sensor_calibration(parse_xml(EXPORT, "cameras.xml"), "cameras.xml", 0)
    assert read.calibration_class == "adjusted" and read.calibration == CAL0


def test_one_sensor_is_taken_without_asking(tmp_path):
    one = EXPORT.replace(
        EXPORT[EXPORT.index('      <sensor id="1"') : EXPORT.index("    </sensors>")], ""
    )
    path = _write(tmp_path, one)
    assert pg.read_calibration(path) == CAL0
    assert pg.read_metashape_xml(path) == CAL0
    np.testing.assert_array_equal(metashape_covariance_from_xml(one)[1], COV0)
    # as the starting camera of a CSV block (before: refused)
    blk = pg.bundle.read_csv_block(_csv_block(tmp_path), calibrations={"c": path})
    assert blk.cameras["c"] == CAL0


def _csv_block(tmp_path):
    d = tmp_path / "blk"
    d.mkdir()
    (d / "images.csv").write_text(
        "id,camera,X0,Y0,Z0,omega_gon,phi_gon,kappa_gon\n1,c,0,0,100,0,0,0\n2,c,30,0,100,0,0,0\n"
    )
    (d / "points.csv").write_text("id,role,X,Y,Z\nA,tie,10,5,0\nB,tie,20,-5,0\n")
    (d / "observations.csv").write_text(
        "image_id,point_id,u,v\n1,A,2100,1700\n1,B,2400,1300\n2,A,1900,1500\n2,B,1000,1200\n"
    )
    return d


def test_several_sensors_need_a_choice_which_lists_them(tmp_path):
    path = _write(tmp_path, EXPORT)
    listing = (
        r"0 'FC300S \(3.61mm\)' \(frame: initial, adjusted\); "
        r"1 'FC6310 \(8.8mm\)' \(frame: initial\)"
    )
    for read in (pg.read_calibration, pg.read_metashape_xml, read_metashape_covariance):
        with pytest.raises(
            pg.FileFormatError, match=rf"2 sensors \({listing}\); choose one with sensor="
        ):
            read(path)
    with pytest.raises(
        pg.FileFormatError, match=rf"no sensor with id or label 'FC300'; .* are {listing}"
    ):
        read_calibration_file(path, sensor="FC300")
    twin = EXPORT.replace('label="FC6310 (8.8mm)"', 'label="FC300S (3.61mm)"')
    with pytest.raises(
        pg.FileFormatError, match=r"2 sensors have the id or label 'FC300S \(3.61mm\)'.*by its id"
    ):
        read_calibration_file(_write(tmp_path, twin), sensor="FC300S (3.61mm)")
    with pytest.warns(MetashapeXMLWarning, match="initial"):
        assert read_calibration_file(_write(tmp_path, twin), sensor=1)[0] == CAL1
    blk = _csv_block(tmp_path)
    with pytest.raises(
        pg.FileFormatError, match=r"calibrations=\{'c': \(path, sensor id or label\)\}"
    ):
        pg.bundle.read_csv_block(blk, calibrations={"c": path})
    with pytest.warns(MetashapeXMLWarning):
        assert pg.bundle.read_csv_block(blk, calibrations={"c": (path, 1)}).cameras["c"] == CAL1
    # a sensor given for a file that has none
    xml = _write(tmp_path, CAL0.to_xml_string(), "c.xml")
    with pytest.raises(pg.InputError, match=r"sensor 0: .* calibration XML of one camera"):
        read_calibration_file(xml, sensor=0)
    with pytest.raises(pg.InputError, match=r"not a Metashape camera export"):
        read_calibration_file(_write(tmp_path, "{}", "c.json"), sensor=0)


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        (
            'label="FC300S (3.61mm)" type="frame"',
            'label="FC300S (3.61mm)" type="fisheye"',
            r"<sensor id=\"0\" label=\"FC300S \(3.61mm\)\"> \(line 5\) is a 'fisheye' camera "
            r"\(the equidistant fisheye",
        ),
        (
            'label="FC300S (3.61mm)" type="frame"',
            'label="FC300S (3.61mm)" type="equisolid_fisheye"',
            r"'equisolid_fisheye' camera \(the equisolid fisheye model\): photogeom reads frame",
        ),
        (
            'label="FC300S (3.61mm)" type="frame"',
            'label="FC300S (3.61mm)" type="spherical"',
            r"'spherical' camera \(the spherical",
        ),
        (
            '<calibration type="frame" class="adjusted">',
            '<calibration type="cylindrical" class="adjusted">',
            r"projection 'cylindrical' is not supported",
        ),
        (
            "<params>f cx cy b1 k1</params>",
            "<params>f cx cy b1 q1</params>",
            r'<sensor id="0" label="FC300S \(3.61mm\)"> \(line 35\): '
            r"<covariance><params> names q1, not",
        ),
        (
            "<coeffs>4 0.1",
            "<coeffs>4 0.7",
            r"not symmetric: entry \(f, cx\) is 0.7 but \(cx, f\) is 0.1",
        ),
        ("<coeffs>4 0.1", "<coeffs>-4 0.1", r"variance of f is negative \(-4.0\)"),
        (
            "0 0 0 1e-08</coeffs>",
            "0 0 0</coeffs>",
            r"24 finite <coeffs> for 5 <params>; expected 25",
        ),
        (
            '<resolution width="4000" height="3000"/>\n          <f>2312.5',
            '<resolution width="4001" height="3000"/>\n          <f>2312.5',
            r"<resolution> width='4001' differs from the sensor's width='4000'",
        ),
        (
            "<cx>11.25</cx>",
            "<cx>11.25</cx><fx>3</fx>",
            r'class="adjusted"> \(line 21\): unknown tag\(s\) <fx>',
        ),
        ("<k4>0.002</k4>", "<k4>0.002</k4><p3>0.001</p3>", r"<p3> is non-zero"),
        (
            '<calibration type="frame" class="initial">',
            '<calibration type="frame" class="adjusted">',
            r"two <calibration class='adjusted'> elements \(line 17\) and \(line 21\)",
        ),
        (
            'class="initial">\n          <resolution',
            'class="other">\n          <resolution',
            r"<calibration class='other'> \(line 17\); Metashape writes class",
        ),
        (
            "<chunk ",
            '<chunk label="A"><sensors><sensor id="0"/></sensors></chunk><chunk ',
            r"camera export with 2 chunks \('A', 'Chunk 1'\); export the cameras of one chunk",
        ),
        (
            '<?xml version="1.0" encoding="UTF-8"?>',
            '<?xml version="1.0"?><!DOCTYPE d [<!ENTITY a "b">]>',
            r"document type declaration",
        ),
    ],
)
def test_refusals_name_the_element(tmp_path, old, new, match):
    assert old in EXPORT
    path = _write(tmp_path, EXPORT.replace(old, new, 1))
    with pytest.raises((pg.FileFormatError, MetashapeXMLWarning), match=match):
        with warnings.catch_warnings():
            warnings.simplefilter("error", MetashapeXMLWarning)  # unknown tags as errors
            read_calibration_file(path, sensor=0)
    if "unknown tag" in match:
        with pytest.raises(pg.FileFormatError, match=match):
            pg.read_metashape_xml(path, sensor=0, strict=True)


def test_a_project_document_without_sensors_is_refused(tmp_path):
    # the doc.xml of a project (.psx) names its chunks' files: no sensors in it
    project = (
        '<document version="2.0.0"><chunks><chunk id="0" path="0/chunk.zip"/></chunks></document>'
    )
    with pytest.raises(
        pg.FileFormatError,
        match=r"<document> without <chunk><sensors><sensor>: not a camera export",
    ):
        pg.read_calibration(_write(tmp_path, project))


def test_a_sensor_without_calibration_or_an_orphan_covariance_is_refused(tmp_path):
    bare = EXPORT.replace(
        EXPORT[
            EXPORT.index(
                '        <calibration type="frame" class="initial">\n          <f>3648.5'
            ) : EXPORT.index("      </sensor>\n    </sensors>")
        ],
        "",
    )
    with pytest.raises(
        pg.FileFormatError,
        match=r'<sensor id="1" label="FC6310 \(8.8mm\)"> \(line 44\) has no <calibration>',
    ):
        read_calibration_file(_write(tmp_path, bare), sensor=1)
    orphan = EXPORT.replace(
        '<calibration type="frame" class="adjusted">', '<calibration type="frame" class="initial">'
    ).replace(
        '<calibration type="frame" class="initial">\n          <resolution width="4000" '
        'height="3000"/>\n          <f>2314.1</f>\n        </calibration>',
        "",
    )
    with pytest.raises(
        pg.FileFormatError, match=r"a <covariance> \(line 32\) but no adjusted calibration"
    ):
        read_calibration_file(_write(tmp_path, orphan), sensor=0)


def test_camera_convert_reads_a_sensor(cli, tmp_path):
    path = _write(tmp_path, EXPORT)
    code, out, err = cli("camera", "convert", path, tmp_path / "a.json")
    assert code != 0
    assert "2 sensors (0 'FC300S (3.61mm)'" in err
    assert "choose one with --sensor ID or --sensor LABEL" in err and "sensor=" not in err
    code, out, err = cli(
        "camera", "convert", path, tmp_path / "a.json", "--sensor", "FC300S (3.61mm)"
    )
    assert code == 0, err
    assert "from sensor 0 'FC300S (3.61mm)' (adjusted calibration)" in out
    data = json.loads((tmp_path / "a.json").read_text())
    assert data["covariance"]["names"] == list(NAMES0)
    np.testing.assert_array_equal(data["covariance"]["matrix"], COV0)
    assert pg.read_calibration(tmp_path / "a.json") == CAL0
    code, out, err = cli("camera", "convert", path, tmp_path / "b.xml", "--sensor", "1")
    assert code == 0, err
    assert "(initial calibration)" in out and "warning:" in err and "initial one" in err
    assert pg.read_metashape_xml(tmp_path / "b.xml") == CAL1
    code, _, err = cli(
        "camera", "convert", tmp_path / "b.xml", tmp_path / "c.json", "--sensor", "1"
    )
    assert code != 0 and "--sensor '1': " in err and "leave --sensor out" in err
    # a command without --sensor points to camera convert
    from photogeom.cli.camera import read_calibration_option

    with pytest.raises(pg.FileFormatError, match=r"--calibration .*camera convert .* --sensor ID"):
        read_calibration_option(path, "--calibration")


_FLOAT = dict(allow_nan=False, allow_infinity=False)


@settings(max_examples=40, deadline=None)
@given(
    f=st.floats(500, 20000, **_FLOAT),
    pp=st.tuples(st.floats(-100, 100, **_FLOAT), st.floats(-100, 100, **_FLOAT)),
    terms=st.lists(st.floats(-0.2, 0.2, **_FLOAT), min_size=6, max_size=6),
    b=st.tuples(st.floats(-5, 5, **_FLOAT), st.floats(-5, 5, **_FLOAT)),
    free=st.lists(st.sampled_from(METASHAPE_ORDER), min_size=1, max_size=11, unique=True),
    seed=st.integers(0, 2**32 - 1),
)
def test_round_trip_equals_the_calibration_xml(f, pp, terms, b, free, seed):
    k1, k2, k3, k4, p1, p2 = terms
    cal = pg.MetashapeCalibration(
        4000,
        3000,
        f,
        cx=pp[0],
        cy=pp[1],
        k1=k1,
        k2=k2,
        k3=k3,
        k4=k4,
        p1=p1,
        p2=p2,
        b1=b[0],
        b2=b[1],
    )
    names = tuple(n for n in METASHAPE_ORDER if n in free)
    A = np.random.default_rng(seed).normal(size=(len(names), len(names)))
    C = A @ A.T
    C = (C + C.T) / 2
    # the sensor as Metashape writes it, every number with 17 significant digits
    terms_xml = "".join(
        f"<{n}>{getattr(cal, n)!r}</{n}>"
        for n in ("f", "cx", "cy", "b1", "b2", "k1", "k2", "k3", "k4", "p1", "p2")
    )
    text = (
        '<document version="1.5.0"><chunk><sensors><sensor id="7" label="cam" type="frame">'
        '<resolution width="4000" height="3000"/><calibration type="frame" class="adjusted">'
        f'<resolution width="4000" height="3000"/>{terms_xml}</calibration>'
        f"<covariance><params>{' '.join(names)}</params>"
        f"<coeffs>{' '.join(repr(float(v)) for v in C.ravel())}</coeffs></covariance>"
        "</sensor></sensors></chunk></document>"
    )
    read = sensor_calibration(parse_xml(text, "export"), "export")
    assert read.calibration == cal and read.sensor_id == "7"
    assert read.covariance[0] == names
    np.testing.assert_array_equal(read.covariance[1], C)
    written = calibration_text(cal, "metashape", covariance=(names, C))
    assert pg.MetashapeCalibration.from_xml_string(written) == cal
    names_x, C_x = metashape_covariance_from_xml(written)
    assert names_x == names
    np.testing.assert_array_equal(C_x, C)


@pytest.mark.parametrize("encoding", ["utf-8", "utf-16"])
def test_the_lines_parser_builds_the_tree_of_elementtree(encoding):
    import xml.etree.ElementTree as ET

    from photogeom.xmlsafe import parse_xml_lines

    data = EXPORT.replace('encoding="UTF-8"', f'encoding="{encoding}"').encode(encoding)
    root, lines = parse_xml_lines(data, "cameras.xml")
    assert ET.tostring(root) == ET.tostring(parse_xml(data, "cameras.xml"))
    # each element's line: the newlines before its start tag, counted in the text
    text = EXPORT
    for el in root.iter("sensor"):
        at = text.index(f'<sensor id="{el.get("id")}"')
        assert lines[id(el)] == text.count("\n", 0, at) + 1
    for bad, match in ((b"<a>", "not well-formed"), (b"", "not well-formed")):
        with pytest.raises(pg.FileFormatError, match=match):
            parse_xml_lines(bad, "x.xml")


_POSE = """      <camera id="{i}" sensor_id="0" component_id="0" label="DJI_{i:05d}">
        <transform>-0.12310895267876176 -0.99222946444830074 0.018024307225944669
          -29.677549141381292 -0.97579423991461833 0.12433783620472236 0.17990470765763514
          -8.9185737325389045 -0.18074785509042671 0.0045598649721814155 -0.98351889687572625
          -2.5813933981741113 0 0 0 1</transform>
        <rotation_covariance>2.2379243963339504e-08 -2.4391806918735771e-09
          -8.3346207902797458e-10 -2.439180691873578e-09 9.7130495805281601e-09
          4.3318462943809853e-10 -8.334620790279752e-10 4.3318462943809838e-10
          9.2393829603982969e-10</rotation_covariance>
        <location_covariance>1.0374823876600216e-06 1.1424223684349538e-06
          -5.5892400680936419e-06 1.1424223684349538e-06 4.973670658522419e-06
          -2.3456960881169798e-05 -5.5892400680936419e-06 -2.3456960881169798e-05
          0.00012152005057046991</location_covariance>
        <orientation>1</orientation>
        <reference x="119.153465857" y="31.623520850999999" z="62.052"
          yaw="101.99999999999999" pitch="0.099999999999993788" roll="-0" enabled="true"/>
      </camera>
"""


def test_an_export_of_a_thousand_images_is_read(tmp_path, cli, monkeypatch):
    # 936 images with their poses and pose covariances, as Metashape writes them: 1.1 MB,
    # over the 1 MiB of a calibration XML (before: "more than 1048576 bytes; a calibration
    # XML is about 1 kB: wrong file?")
    poses = "".join(_POSE.format(i=i) for i in range(936))
    text = EXPORT.replace("    </cameras>", poses + "    </cameras>")
    assert len(text.encode()) > 1 << 20
    path = _write(tmp_path, text)
    assert pg.read_metashape_xml(path, sensor=0) == CAL0
    cal, _, (names, C) = read_calibration_file(path, sensor=0)
    assert cal == CAL0 and names == NAMES0
    np.testing.assert_array_equal(C, COV0)
    np.testing.assert_array_equal(read_metashape_covariance(path, sensor=0)[1], COV0)
    code, out, err = cli("camera", "convert", path, tmp_path / "a.json", "--sensor", "0")
    assert code == 0 and "from sensor 0" in out, err
    # a calibration XML of that size is still refused, and an export over its own limit
    big = CAL0.to_xml_string().replace("<f>", "<!--" + "x" * (1 << 20) + "--><f>")
    with pytest.raises(pg.FileFormatError, match=r"more than 1048576 bytes; a calibration XML"):
        pg.read_calibration(_write(tmp_path, big, "big.xml"))
    from photogeom.camera import metashape

    monkeypatch.setattr(metashape, "MAX_CAMERA_EXPORT_BYTES", 1 << 20)
    with pytest.raises(pg.FileFormatError, match=r"more than 1048576 bytes; .* camera exports"):
        read_calibration_file(path, sensor=0)


def test_camera_convert_parses_an_export_once(tmp_path, cli, monkeypatch):
    # the whole document is parsed once (before: four times, 6.4 s and 477 MB for a 53 MB
    # export of 46 800 images; now 2.7 s and 297 MB); the root is told from the prolog
    import photogeom.xmlsafe as xs

    calls = []
    lines, fromstring = xs.parse_xml_lines, xs.ElementTree.fromstring
    monkeypatch.setattr(xs, "parse_xml_lines", lambda *a: calls.append("lines") or lines(*a))
    monkeypatch.setattr(
        xs.ElementTree, "fromstring", lambda *a, **k: calls.append("tree") or fromstring(*a, **k)
    )
    path = _write(tmp_path, EXPORT)
    code, out, err = cli("camera", "convert", path, tmp_path / "a.json", "--sensor", "0")
    assert code == 0 and "from sensor 0" in out, err
    assert calls == ["lines"]
    calls.clear()
    assert read_calibration_file(path, sensor=0)[0] == CAL0
    assert pg.read_metashape_xml(path, sensor=0) == CAL0
    assert calls == ["lines", "lines"]


def test_the_help_names_the_camera_export(cli):
    for args in (("camera", "convert"), ("camera", "project"), ("orient", "resection")):
        code, out, _ = cli(*args, "--help")
        assert code == 0 and "camera export" in " ".join(out.split()), args


def test_an_id_that_is_another_sensors_label_is_chosen_with_a_prefix(tmp_path, cli):
    # sensor 1 labelled "0": "0" names two sensors; an int or id:/label: names one
    path = _write(tmp_path, EXPORT.replace('label="FC6310 (8.8mm)"', 'label="0"'))
    with pytest.raises(pg.FileFormatError, match=r"write id:0 for .* or label:0 for"):
        read_calibration_file(path, sensor="0")
    assert read_calibration_file(path, sensor=0)[0] == CAL0
    assert read_calibration_file(path, sensor="id:0")[0] == CAL0
    with pytest.warns(MetashapeXMLWarning):
        assert read_calibration_file(path, sensor="label:0")[0] == CAL1
    code, out, err = cli("camera", "convert", path, tmp_path / "a.xml", "--sensor", "label:0")
    assert code == 0 and "from sensor 1 '0' (initial calibration)" in out, err
