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


def test_a_record_pipe_read_twice_in_a_command_is_the_same_record(tmp_path: Path):
    """read_bundle_result read a pipe itself (Path.read_bytes), beside the shared pipe
    reader: in one command a second read of the pipe waited for a new writer, or read what
    that one wrote (another record). It is read once per command, as every other input."""
    import sys
    import threading

    import photogeom as pg
    from photogeom.io import sources
    from photogeom.report.bundle_record import (
        bundle_result_data,
        read_bundle_result,
        write_bundle_result,
    )

    sys.path.insert(0, str(Path(__file__).parent))
    from fifos import fifo_with

    sim = pg.simulate.uav_block(
        "FC300S", seed=3, strips=1, images_per_strip=3, tie_points_per_image=30
    )
    fit = pg.bundle_adjust(sim.block, snooping=False)
    write_bundle_result(bundle_result_data(fit), tmp_path / "a.json")
    first = (tmp_path / "a.json").read_bytes()
    other = first.replace(b'"FC300S"', b'"another camera"')
    assert other != first
    fifo = fifo_with(tmp_path, first, "record.pipe")
    with sources.pipe_reads():
        want = read_bundle_result(fifo)
        assert sources.kept_pipe_bytes(fifo) == first

        def feed() -> None:  # a later writer: not what this command reads
            with open(fifo, "wb") as fh:
                fh.write(other)

        writer = threading.Thread(target=feed, daemon=True)
        writer.start()
        assert read_bundle_result(fifo) == want
    with open(fifo, "rb") as fh:  # let the later writer finish
        fh.read()
    writer.join()
