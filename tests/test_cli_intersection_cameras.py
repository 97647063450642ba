"""`orient intersection --camera a.json,b.json` (one option with a comma, as other
options take lists) said "2 image file(s) but 1 --camera file(s): give one camera per image"
without saying how; the help rendered the option as '--camera <list[Path]>'."""

from __future__ import annotations

from pathlib import Path


def test_comma_in_camera_is_explained(cli, tmp_path: Path):
    img = tmp_path / "i.csv"
    img.write_text("id,x,y\nA,0,0\n")
    code, _, err = cli("orient", "intersection", img, img, "--camera", "a.json,b.json")
    assert code == 2
    assert "repeating the option (--camera cam1.json --camera cam2.json)" in err
    assert "a comma does not separate files" in err


def test_help_shows_a_path_and_says_repeat(cli):
    code, out, _ = cli("orient", "intersection", "--help")
    text = " ".join(out.split())
    assert code == 0 and "--camera <path>" in text and "repeat the option" in text
    assert "--camera <list[Path]>" not in text
