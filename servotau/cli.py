"""The ``servotau`` command line.

Each sub-command lives in the package that owns it and exposes ``register(subparsers)``, which adds
its parser and sets ``func`` (called with the parsed arguments, returning an exit code). Modules are
imported only when their command runs, so ``servotau --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

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
}


EXIT_CODES = """exit codes:
  0    success
  2    error: bad input, configuration or file (the message says what was expected)
  3    safety trip: servotau control stopped and held position
  4    robot lost: servotau control lost the connection to the robot
  130  interrupted (Ctrl-C)"""


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="servotau", description="Torque control without joint-torque sensors.",
                                     epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
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
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(command if command in COMMANDS else None)
    args = parser.parse_args(argv)
    level = logging.DEBUG if args.verbose else logging.INFO
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
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
