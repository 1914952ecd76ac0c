"""servotau.cli: plain-text help of the commands and the exit codes in `servotau --help`."""

import pytest

from servotau.cli import main


def help_text(capsys, *argv: str) -> str:
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--help"])
    assert exc.value.code == 0
    return capsys.readouterr().out


def test_top_level_help_lists_the_exit_codes(capsys):
    """`servotau --help` names every command and the exit codes 0, 2, 3, 4 and 130."""
    text = help_text(capsys)
    for command in ("sim", "control", "demo", "identify", "model", "experiment"):
        assert f"    {command} " in text, command
    codes = text[text.index("exit codes:"):]
    for code, meaning in (("0", "success"), ("2", "error"), ("3", "safety trip"), ("4", "robot lost"),
                          ("130", "interrupted")):
        assert f"  {code} " in codes and meaning in codes, code


@pytest.mark.parametrize("argv", [("sim",), ("demo",), ("identify",), ("identify", "collect"), ("identify", "fit"),
                                  ("model",), ("model", "add"), ("model", "simulate")])
def test_command_help_is_plain_text(capsys, argv):
    """The help of the application commands has no reST markup (no `::`, no double backticks)."""
    text = help_text(capsys, *argv)
    assert f"usage: servotau {' '.join(argv)}" in text
    assert "::" not in text and "``" not in text, text


def _parsers(parser, path=()):
    """Every parser under ``parser`` (sub-commands and their steps), with its command path."""
    import argparse

    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, (*path, name))


def test_every_help_is_plain_text_and_lists_the_exit_codes():
    """Every command and step: no reST markup (roles, double backticks, a literal block's ::), and its exit codes."""
    import re

    from servotau.cli import COMMANDS, build_parser

    seen = []
    for command in COMMANDS:
        for path, parser in _parsers(build_parser(command)):
            if path[:1] != (command,):
                continue
            text = parser.format_help()
            seen.append(" ".join(path))
            assert "``" not in text and not re.search(r"::\s*$", text, re.M), (path, text)
            assert not re.search(r":(class|func|meth|mod|data|attr):`", text), (path, text)
            assert "exit codes:" in text and "  0  " in text, (path, text)
    assert {"model compare", "identify fit", "config init", "ctl", "control"} <= set(seen)


def test_plain_text_removes_rest_markup():
    from servotau.cli import plain_text

    text = plain_text("Usage::\n\n    run ``x``\n::\n\n"
                      "See :class:`~servotau.hal.Backend` and :func:`a.b` and **c** `d`.")
    assert text == "Usage:\n\n    run x\n\nSee Backend and a.b and c d."


def test_version(capsys):
    """`servotau --version` prints the installed distribution's version."""
    from importlib import metadata

    assert main(["--version"]) == 0  # without importing the commands
    assert capsys.readouterr().out == f"servotau {metadata.version('servotau')}\n"
    from servotau.cli import build_parser

    with pytest.raises(SystemExit) as exc:  # the parser's own --version (the one --help lists)
        build_parser("sim").parse_args(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out == f"servotau {metadata.version('servotau')}\n"


def test_the_hal_module_help_is_plain_text(capsys):
    from servotau.hal.robot.cli import main as hal_main

    with pytest.raises(SystemExit):
        hal_main(["--help"])
    text = capsys.readouterr().out
    assert "``" not in text and "exit codes:" in text and "--config DIR" in text
