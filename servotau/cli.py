"""The ``servotau`` command line.

Each sub-command lives in the package that owns it and exposes ``register(subparsers)``, which adds
its parser and sets ``func`` (called with the parsed arguments, returning an exit code). Modules are
imported only when their command runs, so ``servotau --help`` stays fast. Every parser's help is plain
text (:func:`plain_text` removes the reST markup of the docstrings it shows) and lists the exit codes.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import re
import sys
from importlib import metadata

from servotau.errors import ServotauError

# command -> module providing register(subparsers)
COMMANDS = {
    "sim": "servotau.apps.sim",
    "control": "servotau.apps.control",
    "ctl": "servotau.apps.ctl",
    "demo": "servotau.apps.demo",
    "identify": "servotau.apps.identify",
    "model": "servotau.apps.model",
    "certs": "servotau.apps.certs",
    "log": "servotau.apps.log_convert",
    "experiment": "servotau.experiments",
    "config": "servotau.apps.config_cmd",
}

_SUCCESS = "  0    success"
_ERROR = "  2    error: bad input, configuration or file (the message names it and says what was expected)"
_TRIP = "  3    safety trip: the controller held position until released"
_LOST = "  4    robot lost: the controller lost the connection to the robot"
_INTERRUPTED = "  130  interrupted (Ctrl-C)"
EXIT_CODES = "\n".join(["exit codes:", _SUCCESS, _ERROR, _TRIP, _LOST, _INTERRUPTED])
COMMAND_EXIT_CODES = {
    "control": "\n".join(["exit codes:", "  0    success: the task ended, or a first Ctrl-C / SIGTERM / `ctl stop` "
                           "brought it to rest", _ERROR, _TRIP, _LOST,
                           "  130  released before the end of the task (a second Ctrl-C or SIGTERM)"]),
    "demo": EXIT_CODES + "\n  (demo: the controller's exit code)",
    "ctl": "\n".join(["exit codes:", "  0    the action was done",
                      "  1    the action was refused (the answer says why)", "  2    nobody answered, or bad input",
                      _INTERRUPTED]),
    "sim": "\n".join(["exit codes:", _SUCCESS, "  1    the robot could not be served", _ERROR, _INTERRUPTED]),
}
"""Each command's exit codes (the others: :data:`GENERIC_EXIT_CODES`)."""
GENERIC_EXIT_CODES = "\n".join(["exit codes:", _SUCCESS, _ERROR, _INTERRUPTED])

_ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|exc|obj|ref|doc):`(~?)([^`<]+?)(?:\s*<[^>]*>)?`")


def plain_text(text: str | None) -> str | None:
    """``text`` without reST markup: ``:class:`~a.B``` -> ``B``, double and single backticks, ``**bold**``, and
    a literal block's ``::`` (``Usage::`` -> ``Usage:``, a line of ``::`` alone removed)."""
    if not text:
        return text
    text = _ROLE.sub(lambda m: m.group(2).rsplit(".", 1)[-1] if m.group(1) else m.group(2), text)
    text = text.replace("``", "")
    text = re.sub(r"`([^`]+)`_?", r"\1", text)
    text = re.sub(r"\*\*([^*]+)\*\*", r"\1", text)
    text = re.sub(r"^[ \t]*::[ \t]*\n", "", text, flags=re.M)
    text = re.sub(r"\s*::[ \t]*$", ":", text, flags=re.M)
    return text


def _plain_parser(parser: argparse.ArgumentParser, epilog: str) -> None:
    """Make ``parser`` and its sub-parsers' help plain text, each with ``epilog`` (the exit codes) unless it has
    its own."""
    parser.description = plain_text(parser.description)
    parser.epilog = plain_text(parser.epilog) if parser.epilog else epilog
    if parser.formatter_class is argparse.HelpFormatter:  # keep the epilog's lines
        parser.formatter_class = argparse.RawDescriptionHelpFormatter
    for action in parser._actions:
        action.help = plain_text(action.help) if isinstance(action.help, str) else action.help
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                choice.help = plain_text(choice.help)
            for sub in action.choices.values():
                _plain_parser(sub, epilog)


def version() -> str:
    """The installed distribution's version."""
    try:
        return metadata.version("servotau")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="servotau", description="Torque control without joint-torque sensors.",
                                     epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"servotau {version()}")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, module in COMMANDS.items():
        if only is not None and name != only:
            sub.add_parser(name, help=f"(see servotau {name} --help)")
            continue
        try:
            importlib.import_module(module).register(sub)
        except ModuleNotFoundError as exc:
            if exc.name != module:
                raise
            sub.add_parser(name, help="(not available in this version)")
    for name, command in sub.choices.items():
        _plain_parser(command, COMMAND_EXIT_CODES.get(name, GENERIC_EXIT_CODES))
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    command = next((a for a in argv if not a.startswith("-")), None)
    if command is None and "--version" in argv:  # without importing every command
        print(f"servotau {version()}")
        return 0
    parser = build_parser(command if command in COMMANDS else None)
    args = parser.parse_args(argv)
    level = logging.DEBUG if args.verbose else logging.INFO
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    from servotau.config_paths import show_loaded_files

    show_loaded_files()  # every config file read is named on stderr
    if not hasattr(args, "func"):
        parser.error(f"'{args.command}' is not available in this version")
    try:
        return int(args.func(args) or 0)
    except ServotauError as exc:
        print(f"servotau {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"servotau {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
