"""`grid evaluate` / sweep / report ran for seconds to minutes (simulating and
adjusting a preset, a grid-size sweep of several re-adjustments) with nothing on a terminal;
now a spinner names the stage (on a terminal only, never in pipes or logs)."""

from __future__ import annotations

ARGS = ("--preset", "FC300S", "--strips", "1", "--images-per-strip", "5")


def test_sweep_shows_its_stages_on_a_terminal_only(cli, terminal_stderr):
    args = ("grid", "sweep", *ARGS, "--spacings", "500,1000")
    code, _, err = cli(*args)
    assert code == 0 and err == ""  # not a terminal: nothing drawn
    buf = terminal_stderr()
    code, _, err = cli(*args)
    assert code == 0, err
    shown = buf.getvalue()
    assert "adjusting the FC300S block" in shown
    assert "sweep: grids and re-adjustment at 2 spacings" in shown


def test_evaluate_shows_the_grid_stage(cli, terminal_stderr):
    buf = terminal_stderr()
    code, _, err = cli("grid", "evaluate", *ARGS, "--spacing", "1000")
    assert code == 0, err
    assert "fitting grids of 1000 px" in buf.getvalue()
