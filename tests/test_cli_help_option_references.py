"""An option's help that qualifies it by another option ("with --X", "not with --X") names
an option of the same command: shared option texts once told `grid sweep` users that
``--sigma-constraint vce`` was "not with --in-adjustment", an option sweep does not have."""

import re

import typer

from photogeom.cli.main import app

_QUALIFIED = re.compile(r"\b[Ww]ith (--[a-z][a-z0-9-]*)")


def _commands():
    out = []

    def walk(cmd, path):
        if hasattr(cmd, "list_commands"):
            ctx = cmd.context_class(cmd)
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), [*path, name])
            return
        out.append((" ".join(path), cmd))

    walk(typer.main.get_command(app), [])
    return out


def test_qualifying_options_in_help_texts_belong_to_the_command():
    commands = _commands()
    assert len(commands) > 25
    wrong = []
    for path, cmd in commands:
        names = {n for p in cmd.params for n in (*p.opts, *p.secondary_opts)}
        for p in cmd.params:
            for ref in _QUALIFIED.findall(getattr(p, "help", None) or ""):
                if ref not in names:
                    wrong.append(f"photogeom {path} {p.opts[0]}: {ref}")
    assert not wrong, wrong
