"""A CSV block folder whose observations.csv holds one (image, point) twice:
it was refused only later by ``Block.validate`` ("image 0 observes point 0 2 times"),
naming neither the file nor the lines; the reader now names the file and both lines."""

from __future__ import annotations

from pathlib import Path

import pytest

from photogeom import datasets
from photogeom.bundle import read_bal, read_csv_block, write_csv_block
from photogeom.errors import FileFormatError

BAL = Path(datasets.__file__).parent / "data" / "bundle" / "dubrovnik-3-7-pre.txt"


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    d = tmp_path / "block"
    write_csv_block(read_bal(BAL), d)
    return d


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def test_a_repeated_observation_names_the_file_and_both_lines(folder: Path):
    obs = folder / "observations.csv"
    lines = _lines(obs)
    data = [k for k, ln in enumerate(lines) if ln and not ln.startswith("#")][1:]  # rows
    first = data[4]  # the 5th observation, repeated further down with other numbers
    image, point = lines[first].split(",")[:2]
    lines.insert(data[10] + 1, f"{image},{point},10.5,20.5,1.0")
    obs.write_text("\n".join(lines) + "\n")
    with pytest.raises(FileFormatError) as info:
        read_csv_block(folder)
    msg = str(info.value)
    assert f"{obs}, lines {first + 1} and {data[10] + 2}:" in msg
    assert f"image {image}'s observation of point {point}" in msg


def test_bundle_adjust_names_the_lines(cli, folder: Path):
    obs = folder / "observations.csv"
    lines = _lines(obs)
    row = next(k for k, ln in enumerate(lines) if ln and not ln.startswith("#")) + 1
    lines.append(lines[row])
    obs.write_text("\n".join(lines) + "\n")
    code, _, err = cli("bundle", "adjust", folder, "--datum", "free")
    assert code == 2
    assert f"lines {row + 1} and {len(lines)}" in err and "observations.csv" in err


def test_distinct_observations_still_read(folder: Path):
    assert read_csv_block(folder).n_observations == read_bal(BAL).n_observations


def test_a_header_ending_in_a_separator_names_the_column_and_the_fix(folder: Path, tmp_path):
    # a spreadsheet's export with a separator after the last column ("id,x,y,z," /
    # "image_id;point_id;u;v;sigma;"): refused before as "the header has an empty column
    # name", naming neither the column nor what to do; both CSV readers now name them
    from photogeom.io.points import read_points

    obs = folder / "observations.csv"
    obs.write_text("\n".join(ln.replace(",", ";") + ";" for ln in _lines(obs)) + "\n")
    with pytest.raises(FileFormatError, match=r"observations.csv, line \d+: the header ends in a "
                       r"separator \(';'\): its column 6 has no name; remove the separator at "
                       r"the end of the lines"):  # fmt: skip
        read_csv_block(folder)
    pts = tmp_path / "p.csv"
    pts.write_text("id,x,y,z,\nA,1,2,3,\n")
    with pytest.raises(FileFormatError, match=r"p.csv, line 1: the header ends in a separator "
                       r"\(','\): its column 5 has no name"):  # fmt: skip
        read_points(pts)
    pts.write_text("id,,y,z\nA,1,2,3\n")
    with pytest.raises(FileFormatError, match=r"empty column name \(column 2\): name it"):
        read_points(pts)
