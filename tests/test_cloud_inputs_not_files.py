"""LAS/LAZ inputs that are not regular files: a pipe, a device or a folder was
reported as "point cloud F does not exist"; a cloud is read with seeks (header, chunks,
two passes), so each is now refused by what it is."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from photogeom.errors import InputError
from photogeom.io import cloud_info


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_pipe_is_refused_by_name(cli, tmp_path: Path):
    fifo = tmp_path / "scan.laz"
    os.mkfifo(fifo)  # never opened: the reader refuses it from its stat
    with pytest.raises(InputError, match="it is a pipe, and a LAS/LAZ file is read with seeks"):
        cloud_info(fifo)
    code, _, err = cli("cloud", "info", fifo)
    assert code == 2
    assert f"cannot read point cloud {fifo}: it is a pipe" in err
    assert "regular file" in err


def test_a_folder_and_a_device_are_refused_by_name(tmp_path: Path):
    with pytest.raises(InputError, match="is a folder; give a LAS/LAZ file"):
        cloud_info(tmp_path)
    if Path("/dev/null").exists():
        with pytest.raises(InputError, match="/dev/null: it is a device"):
            cloud_info("/dev/null")
