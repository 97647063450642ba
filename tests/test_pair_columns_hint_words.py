"""The pair reader's "cannot tell which columns" error names the keywords of the function
called, and the command line its options.

Before, ``pg.io.read_point_pairs`` said "(or name them, e.g. --source-cols x2,y2
--target-cols x1,y1)": options of the command line, to a Python caller, whose keywords are
``source_columns`` and ``target_columns``.
"""

from __future__ import annotations

import re

import pytest

from photogeom.errors import FileFormatError
from photogeom.io import read_point_pairs


@pytest.fixture
def unnamed(tmp_path):
    p = tmp_path / "pairs.csv"
    p.write_text("id,a,b,c,d\n1,0,0,1,1\n2,1,0,2,1\n3,0,1,1,2\n")
    return p


def test_the_library_names_its_keywords(unnamed):
    with pytest.raises(FileFormatError) as exc:
        read_point_pairs(unnamed)
    msg = str(exc.value)
    assert msg.endswith("(or name them, e.g. source_columns='x2,y2', target_columns='x1,y1')")
    assert not re.search(r"(?<![\w-])--[a-z]", msg), msg
    # the keywords it names work
    pairs = read_point_pairs(unnamed, source_columns="a,b", target_columns="c,d")
    assert pairs.source_columns == ("a", "b") and pairs.target_columns == ("c", "d")


@pytest.mark.parametrize(
    "command",
    [("transform", "estimate", "affine2d"), ("orient", "absolute")],
)
def test_the_command_line_names_its_options(cli, unnamed, command):
    code, _, err = cli(*command, unnamed)
    assert code == 2
    assert err.rstrip().endswith("(or name them, e.g. --source-cols x2,y2 --target-cols x1,y1)")
    assert "source_columns" not in err
