"""Every subcommand's --help prints its options (help texts are plain text shared with Blender: "1%" once crashed
argparse's own %-formatting and hid every bake option)."""
import argparse

import pytest

from gs_ibl_addon.cli import build_parser, main


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_every_subcommand_is_listed():
    assert set(_subcommands()) >= {"info", "render", "cubemap", "bake", "convert", "sample"}


@pytest.mark.parametrize("command", [None, *sorted(_subcommands())])
def test_help_prints_every_option(command, capsys):
    with pytest.raises(SystemExit) as e:
        main(([command] if command else []) + ["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    parser = build_parser() if command is None else _subcommands()[command]
    for action in parser._actions:
        for flag in action.option_strings:
            assert flag in out, (command, flag)
        if action.help and action.help != argparse.SUPPRESS:
            first_word = action.help.split()[0]
            assert first_word in out, (command, action.dest)
    assert "%%" not in out  # escaped once, shown once
