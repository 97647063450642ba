"""``photogeom bundle report /dev/zero`` read the device until memory ran out;
a device is now refused by name. A record from a pipe is read once."""

from __future__ import annotations

from pathlib import Path

import pytest


def test_bundle_report_refuses_a_device(cli, tmp_path: Path):
    if not Path("/dev/null").exists():
        pytest.skip("no /dev/null")
    code, _, err = cli("bundle", "report", "/dev/null", "-o", tmp_path / "r.html")
    assert code == 2
    assert "cannot read result record /dev/null: it is a device" in err
    assert not (tmp_path / "r.html").exists()
