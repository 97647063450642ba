"""Invariance: point ids that only look alike are never merged, and the error
says why they do not match."""

import json

import numpy as np
import pytest

from photogeom.errors import InputError
from photogeom.io import join_points, parse_points

NFD = "e\u0301"  # 'e' + combining acute accent
NFC = "\u00e9"  # the composed letter


def test_ids_in_different_unicode_forms_are_named_as_such():
    # 'é' composed and decomposed print alike: the error listed "only in source: é; only in
    # target: é" and nothing else
    a = parse_points(f"id,x,y\n{NFD},0,0\n2,1,0\n3,0,1\n")
    b = parse_points(f"id,X,Y\n{NFC},0,0\n2,1,0\n3,0,1\n")
    with pytest.raises(InputError) as exc:
        join_points(a, b)
    msg = str(exc.value)
    assert r"'e\u0301' in source vs '\xe9' in target" in msg
    assert "allow_unmatched=True" in msg
    pairs = join_points(a, b, allow_unmatched=True)  # left out, never merged
    assert pairs.ids == ("2", "3")
    assert any(r"'e\u0301'" in note for note in pairs.notes)


def test_ids_alike_only_in_digits_get_no_unicode_hint():
    a = parse_points("id,x,y\n7,0,0\n2,1,0\n3,0,1\n")
    b = parse_points("id,X,Y\n007,0,0\n2,1,0\n3,0,1\n")
    with pytest.raises(InputError) as exc:
        join_points(a, b)
    assert "only in source: 7" in str(exc.value) and "Unicode" not in str(exc.value)


def _pair_files(tmp_path, src_ids, dst_ids):
    rng = np.random.default_rng(0)
    x = rng.normal(size=(len(src_ids), 3)) * 50
    X = 1.1 * x + [100.0, 200.0, 30.0]
    src, dst = tmp_path / "src.csv", tmp_path / "dst.csv"
    src.write_text("id,x,y,z\n" + "".join(
        f"{i},{p[0]},{p[1]},{p[2]}\n" for i, p in zip(src_ids, x)), encoding="utf-8")
    dst.write_text("id,X,Y,Z\n" + "".join(
        f"{i},{p[0]},{p[1]},{p[2]}\n" for i, p in zip(dst_ids, X)), encoding="utf-8")
    return src, dst


@pytest.mark.parametrize(
    "command", [("orient", "absolute"), ("transform", "estimate", "similarity3d")]
)
def test_command_line_names_its_option_for_unmatched_ids(cli, tmp_path, command):
    # the message named the library's wording ("allow unmatched points"), not the option
    ids = ["1", NFD, "3", "4", "5"]
    src, dst = _pair_files(tmp_path, ids, ["1", NFC, "3", "4", "5"])
    code, out, err = cli(*command, src, dst)
    assert code != 0
    assert "--allow-unmatched" in err and "allow_unmatched=True" not in err
    assert r"'e\u0301' in " in err
    code, out, err = cli(*command, src, dst, "--allow-unmatched", "--json")
    assert code == 0, err
    assert json.loads(out)


@pytest.mark.parametrize(
    ("written", "known"),
    [(NFD, NFC), ("P\u00a01", "P 1"), ("\uff17", "7x")],
    ids=["decomposed", "no-break-space", "full-width"],
)
def test_csv_block_names_look_alike_ids(tmp_path, written, known):
    # the error printed 'é' is not one of the point ids, with 'é' among them
    from photogeom.bundle import read_csv_block
    from photogeom.errors import FileFormatError

    if known == "7x":  # a full-width 7 against a text id 7 (text column: quoted)
        known = '"7"'
    files = {
        "cameras.csv": "camera,width,height,f\nc,100,80,90\n",
        "images.csv": "id,camera,X0,Y0,Z0,omega_deg,phi_deg,kappa_deg\n1,c,0,0,10,0,0,0\n",
        "points.csv": f"id,role,X,Y,Z\nq,tie,0,0,0\n{known},tie,1,1,0\n",
        "observations.csv": f"image_id,point_id,u,v\n1,q,49.5,39.5\n1,{written},58,31\n",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text, encoding="utf-8")
    with pytest.raises(FileFormatError) as exc:
        read_csv_block(tmp_path)
    msg = str(exc.value)
    assert "line 3: point_id" in msg
    assert f"written with other characters: {written!a}" in msg


def test_csv_block_unknown_id_without_a_look_alike_has_no_hint(tmp_path):
    from photogeom.bundle import read_csv_block
    from photogeom.errors import FileFormatError

    files = {
        "cameras.csv": "camera,width,height,f\nc,100,80,90\n",
        "images.csv": "id,camera,X0,Y0,Z0,omega_deg,phi_deg,kappa_deg\n1,c,0,0,10,0,0,0\n",
        "points.csv": "id,role,X,Y,Z\nq,tie,0,0,0\nr,tie,1,1,0\n",
        "observations.csv": f"image_id,point_id,u,v\n1,q,49.5,39.5\n1,{NFC},58,31\n",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text, encoding="utf-8")
    with pytest.raises(FileFormatError) as exc:
        read_csv_block(tmp_path)
    assert "other characters" not in str(exc.value)


def test_csv_block_names_an_id_that_differs_in_letter_case_only(tmp_path):
    # before: "image_id 'dsc1.jpg' is not one of the image (images.csv) ids", with
    # 'DSC1.JPG' among them and no word of it (an id typed by hand, a name from another tool)
    from photogeom.bundle import read_csv_block
    from photogeom.errors import FileFormatError

    files = {
        "cameras.csv": "camera,width,height,f\nc,100,80,90\n",
        "images.csv": "id,camera,X0,Y0,Z0,omega_deg,phi_deg,kappa_deg\nDSC1.JPG,c,0,0,10,0,0,0\n",
        "points.csv": "id,role,X,Y,Z\nq,tie,0,0,0\n",
        "observations.csv": "image_id,point_id,u,v\nDSC1.JPG,q,49.5,39.5\ndsc1.jpg,q,58,31\n",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text, encoding="utf-8")
    with pytest.raises(FileFormatError) as exc:
        read_csv_block(tmp_path)
    assert str(exc.value).endswith(
        "line 3: image_id 'dsc1.jpg' is not one of the image (images.csv) ids (it differs from "
        "the id 'DSC1.JPG' in letter case only; ids are compared as written: write the id "
        "alike in both files)"
    )
