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
