"""Ctrl-C ends a command with exit code 130 and leaves its output files as they
were (docs/cli.md, exit codes)."""

from __future__ import annotations

from pathlib import Path

from photogeom import datasets


def test_interrupt_exits_130_and_keeps_outputs(cli, tmp_path: Path, monkeypatch):
    import photogeom.orientation as orientation

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(orientation, "absolute_orientation", interrupted)
    params, rep = tmp_path / "p.json", tmp_path / "r.html"
    params.write_text("old")
    code, _, _ = cli("orient", "absolute", datasets.path("lidar_wang2014"),
                     "--output-params", params, "--report", rep)
    assert code == 130
    assert params.read_text() == "old" and not rep.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.json"]
