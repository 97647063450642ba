"""Review 11 (invariance): point ids that only look alike are never merged, and the error
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
