"""``python -m servotau.hal``: serve a robot built from an import string (the robot side of docs/protocol.md)."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from servotau.config import ConfigFiles, Section
from servotau.config_paths import show_loaded_files
from servotau.errors import ServotauError

from ..config import import_object
from ..errors import HalError
from ..registry import hal_section
from ..wire.security import Security, check_endpoints, security_from_section
from ..wire.session import DEFAULT_ENDPOINT
from .config import CLOCKS, MODES, ServerConfig
from .firmware import SafetyConfig
from .server import serve

EXIT_CODES = """exit codes:
  0    served, then stopped (SIGINT, SIGTERM or --max-ticks); the server's status is printed as JSON
  2    error: a bad option, config file or setting (the message names it), before the robot moves"""


def _safety_of(a) -> SafetyConfig:
    """[hal.safety] from ``--safety`` (JSON) and the watchdog options, which override it. ``--hold-after`` and
    ``--servo-off-after`` also set their lock-step twins unless those are given (as options or in ``--safety``)."""
    try:
        extra = json.loads(a.safety)
    except ValueError as exc:
        raise HalError(f"--safety {a.safety!r}: expected a JSON object of [hal.safety] settings ({exc})") from None
    if not isinstance(extra, dict):
        raise HalError(f"--safety {a.safety!r}: expected a JSON object of [hal.safety] settings")
    given = {"hold_after": a.hold_after, "servo_off_after": a.servo_off_after,
             "lockstep_hold_after": a.lockstep_hold_after, "lockstep_servo_off_after": a.lockstep_servo_off_after}
    for twin, value in (("lockstep_hold_after", a.hold_after), ("lockstep_servo_off_after", a.servo_off_after)):
        if given[twin] is None and twin not in extra:
            given[twin] = value
    return SafetyConfig.from_section(
        Section({**extra, **{k: v for k, v in given.items() if v is not None}}, "--safety", ""))


def main(argv: list[str] | None = None) -> int:
    """``python -m servotau.hal``: serve a robot built from an import string."""
    p = argparse.ArgumentParser(prog="python -m servotau.hal", description=__doc__.split("\n")[0].replace("``", ""),
                                epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robot", required=True, help="robot factory, 'module:callable'")
    p.add_argument("--config", metavar="DIR", help="config folder: --scenario and --security name files of DIR (else "
                                                   "of the packaged defaults), not of the working folder")
    p.add_argument("--scenario", help="scenario config path passed to the factory")
    p.add_argument("--kwargs", default="{}", help="JSON object of keyword arguments for the factory")
    p.add_argument("--name", help="robot name in the keys (default: RobotInfo.name)")
    p.add_argument("--listen", action="append", help=f"zenoh endpoint to listen on (default {DEFAULT_ENDPOINT})")
    p.add_argument("--connect", action="append", default=[], help="zenoh endpoint to connect to (router)")
    p.add_argument("--mode", default=ServerConfig.mode, choices=MODES)
    p.add_argument("--clock", default=ServerConfig.clock, choices=CLOCKS)
    p.add_argument("--log", help="Parquet log of what was served")
    p.add_argument("--max-ticks", type=int)
    p.add_argument("--no-truth", action="store_true", help="do not publish the ground truth")
    p.add_argument("--realtime-priority", type=int, default=ServerConfig.realtime_priority,
                   help="SCHED_FIFO priority 1..99 of the process (0: ordinary scheduling; needs root or "
                        "CAP_SYS_NICE)")
    p.add_argument("--hold-after", type=float, help=f"[s] (default {SafetyConfig.hold_after})")
    p.add_argument("--servo-off-after", type=float, help="[s] no fresh command: servo off (default: never)")
    p.add_argument("--lockstep-hold-after", type=float, help="[s] lock-step watchdog (default: --hold-after)")
    p.add_argument("--lockstep-servo-off-after", type=float, help="[s] lock-step (default: --servo-off-after)")
    p.add_argument("--safety", default="{}", help="JSON object of [hal.safety] settings (hal/robot/safety.py), "
                                                  'e.g. \'{"limit_action": "trip", "max_command_age_ticks": 5}\'; '
                                                  "the options above override it")
    p.add_argument("--ready-file", help="touched once the robot is served (for scripts and tests)")
    p.add_argument("--security", metavar="HAL_TOML", help="secure the session with the tls, auth, access and "
                   "insecure_network entries of [hal.server] in this file (docs/real_backend.md)")
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s: %(message)s")
    listen = a.listen if a.listen is not None else ([] if a.connect else [DEFAULT_ENDPOINT])
    show_loaded_files()
    try:  # before anything is built or served: a bad file or field is a one-line error
        if a.config is not None:  # the files named on the command line come from the config folder
            files = ConfigFiles.create(a.config)
            print(files.describe(), file=sys.stderr, flush=True)
            a.scenario = str(files.path(a.scenario)) if a.scenario else None
            a.security = str(files.path(a.security)) if a.security else None
        security = security_from_section(hal_section(a.security).section("server", {}), robot_side=True) \
            if a.security else Security()
        check_endpoints(security, [*listen, *a.connect], robot_side=True)
        safety = _safety_of(a)
    except ServotauError as exc:
        print(f"python -m servotau.hal: error: {exc}", file=sys.stderr)
        return 2
    factory = import_object(a.robot)
    kwargs = json.loads(a.kwargs)
    robot = factory(a.scenario, **kwargs) if a.scenario else factory(**kwargs)
    cfg = ServerConfig(robot=a.name, listen=tuple(listen), connect=tuple(a.connect), mode=a.mode, clock=a.clock,
                       safety=safety,
                       log=a.log, max_ticks=a.max_ticks,
                       publish_truth=not a.no_truth, realtime_priority=a.realtime_priority, security=security)
    ready = (lambda: Path(a.ready_file).touch()) if a.ready_file else None
    try:  # settings checked against the robot (joint names of [hal.safety.joints]) fail here, before it moves
        server = serve(robot, cfg, ready)
    except ServotauError as exc:
        print(f"python -m servotau.hal: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(server.status()), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
