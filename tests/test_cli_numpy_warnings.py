"""Numpy's floating-point warnings raised in photogeom's code reached the command
line with library source lines before the named error (orient absolute on coordinates of
1e200: 'absolute_direct.py:398: RuntimeWarning: overflow encountered in matmul' and the
code line, then 'error: ... overflow float64 ...')."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import photogeom
from photogeom.cli import main as cli_main


def test_overflow_gives_the_error_line_only(tmp_path: Path):
    pts = tmp_path / "huge.csv"
    pts.write_text("id,x,y,z,X,Y,Z\n1,1e200,0,0,1,1,1\n2,0,1e200,0,2,1,1\n"
                   "3,0,0,1e200,1,2,1\n4,1e200,1e200,0,2,2,2\n")
    # a process of its own: Python's warning display as on the command line (pytest records
    # warnings instead of printing them)
    env = {**os.environ, "PYTHONPATH": str(Path(photogeom.__file__).parents[1])}
    r = subprocess.run([sys.executable, "-m", "photogeom", "orient", "absolute", str(pts)],
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 2
    assert r.stderr.startswith("error: absolute orientation: source coordinates up to 1e+200")
    assert "RuntimeWarning" not in r.stderr and "absolute_direct.py" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_plain_runtime_warnings_of_photogeom_are_deferred_not_dropped(capsys):
    """numpy's warnings in photogeom's code wait for the end of the command: shown once each
    when it finished without a named error or a warning of photogeom's own, else dropped."""
    from photogeom.rpc.domain import LocalizationWarning

    inside = str(Path(photogeom.__file__).parent / "orientation" / "x.py")
    shown, numeric = [], cli_main.NumericWarnings()

    def python_display(*args, **kwargs):
        shown.append(args[1])

    for _ in range(2):
        cli_main._show_warning(python_display, numeric, "overflow", RuntimeWarning, inside, 1)
    assert shown == [] and capsys.readouterr().err == "" and numeric.texts == ["overflow"]
    numeric.show()
    err = capsys.readouterr().err
    assert err.count("warning: numerical: overflow") == 1 and "NaN" in err
    outside = "/elsewhere/x.py"
    cli_main._show_warning(python_display, numeric, "overflow", RuntimeWarning, outside, 1)
    assert shown == [RuntimeWarning]  # not photogeom's code: Python shows it
    cli_main._show_warning(python_display, numeric, "2 points did not converge",
                           LocalizationWarning, inside, 1)
    assert capsys.readouterr().err.startswith("warning: 2 points did not converge")
    numeric.show()  # photogeom named the cause: no numeric line
    assert capsys.readouterr().err == ""


def test_a_finished_command_shows_its_numeric_warnings(monkeypatch, tmp_path: Path, capsys):
    """A command that ends well after a floating-point warning in photogeom's code says so
    (its results may hold NaN); the warning is not lost."""
    import warnings

    import typer

    inside = str(Path(photogeom.__file__).parent / "orientation" / "x.py")
    app = typer.Typer()

    @app.command()
    def run() -> None:
        warnings.warn_explicit("invalid value encountered in divide", RuntimeWarning, inside, 1)

    monkeypatch.setattr(cli_main, "app", app)
    try:
        cli_main.main([])
    except SystemExit as exc:
        assert exc.code in (0, None)
    err = capsys.readouterr().err
    assert "warning: numerical: invalid value encountered in divide" in err


def test_rpc_localize_prints_its_own_warnings_only(cli, tmp_path: Path):
    from photogeom import datasets

    rpc = datasets.path("lecture_fiducials").parent / "rpc" / "rpc_IKONOS.txt"
    pts = tmp_path / "px.csv"
    pts.write_text("id,col,row\n1,100,200\n2,5000,6000\n")
    code, _, err = cli("rpc", "localize", rpc, pts, "--height", "1e300")
    assert code == 0
    lines = err.strip().splitlines()
    assert all(ln.startswith("warning: ") for ln in lines)
    assert any("did not converge" in ln for ln in lines)
    assert not any("overflow encountered" in ln or "invalid value" in ln for ln in lines), err
