"""Block writers onto paths they cannot write: a named OutputError, nothing written."""

from __future__ import annotations

import pytest

import photogeom as pg
from photogeom.bundle import write_colmap, write_csv_block
from photogeom.bundle.io_formats import check_block_target, write_files
from photogeom.errors import OutputError


@pytest.fixture(scope="module")
def block():
    return pg.simulate.uav_block(
        "FC6310", seed=1, strips=2, images_per_strip=4, tie_points_per_image=60
    ).block


def _tree(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


@pytest.mark.parametrize("write", [write_csv_block, write_colmap])
def test_library_writers_onto_a_file(block, tmp_path, write):
    b = block
    f = tmp_path / "afile"
    f.write_text("keep")
    kw = {"drop_extras": True} if write is write_colmap else {}
    with pytest.raises(OutputError, match="afile: it is a file, not a folder"):
        write(b, f, **kw)
    with pytest.raises(OutputError, match="afile is a file, not a folder"):
        write(b, f / "sub", **kw)
    assert f.read_text() == "keep"
    write(b, tmp_path / "new" / "deeper", **kw)  # missing folders are created
    assert len(list((tmp_path / "new" / "deeper").iterdir())) >= 3


def test_write_files_removes_the_folders_it_made(tmp_path):
    (tmp_path / "adir").mkdir()
    with pytest.raises(OutputError, match="adir"):
        write_files(
            {tmp_path / "n" / "m" / "x.txt": b"x", tmp_path / "adir": b"y"},
            folders=[tmp_path / "n" / "m"],
        )
    assert _tree(tmp_path) == ["adir"]


def _record(folder):
    """A record of a joint adjustment with grids in ``folder`` (its settings and a file)."""
    rec = folder / "joint_adjustment"
    rec.mkdir(parents=True)
    (rec / "settings.json").write_text("{}")
    (rec / "observations.csv").write_text("image_id,point_id,u,v\n")
    return rec


def test_write_files_is_a_plain_batch_writer_that_keeps_other_files(block, tmp_path):
    # a file named observations.csv written by the generic batch writer (a --result or
    # --report of that name) is no CSV block: the record beside it stays (before, it was
    # removed as a stale record of a block written there)
    rec = _record(tmp_path / "out")
    write_files({tmp_path / "out" / "observations.csv": b"image_id,point_id,u,v\n"})
    assert sorted(p.name for p in rec.iterdir()) == ["observations.csv", "settings.json"]
    # a CSV block without a record written there removes it: it was another block's
    write_csv_block(block, tmp_path / "out")
    assert not rec.exists()
    _record(tmp_path / "blk")
    pg.bundle.write_block(block, tmp_path / "blk", kind="csv")
    assert not (tmp_path / "blk" / "joint_adjustment").exists()


def test_check_block_target_names_the_option(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(OutputError, match=r"^-o: cannot write .*f: it is a file, not a folder"):
        check_block_target(tmp_path / "f", "csv", "-o")
    with pytest.raises(OutputError, match="it is a folder; a BAL block is one file"):
        check_block_target(tmp_path, "bal")
    with pytest.raises(OutputError, match="does not exist; create it first"):
        check_block_target(tmp_path / "no" / "x.bal", "bal")
    check_block_target(tmp_path / "new" / "folder", "colmap")  # fine: created when written
    check_block_target(tmp_path / "x.bal", "bal")
