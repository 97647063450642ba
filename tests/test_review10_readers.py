"""Readers under hostile input (review 10): work linear in the input, named refusals."""

from __future__ import annotations

import pytest

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
