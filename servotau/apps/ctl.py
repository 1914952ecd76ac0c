"""``servotau ctl``: the operator's commands to a running controller (or robot).

``servotau control`` serves these on its own Zenoh session, with the same authorisation as its robot link::

    servotau ctl status                # the controller's state (running, tripped, holding, stopping, ...), its
                                       # robot time, mode and phase
    servotau ctl torque                # switch to torque mode (bumpless; refused while a trip is latched)
    servotau ctl position              # switch to position mode
    servotau ctl start TASK            # replace the running task: the reference comes to rest, then TASK
                                       # (a name of config/tasks/, a file or module:attribute the controller can
                                       # read; refused if it is infeasible from there)
    servotau ctl stop                  # end the run smoothly: reference at rest, position mode, log closed (exit 0)
    servotau ctl reset                 # after a safety trip: position control at the held posture
                                       # (refused, with the reason, while the trip's cause is still there)
    servotau ctl release               # end the controller at once (its log closed; exit code 3 after a trip)
    servotau ctl reset --robot-side    # reset the robot's own latched fault (servo off) instead

Each sends a Zenoh query with the JSON payload ``{"action": ...}`` (``start``: also ``"task"``) to
``servotau/v1/<robot>/controller/operator`` (served by the controller process) or, with ``--robot-side``, to
``servotau/v1/<robot>/operator`` (served by the robot process), through the robot's endpoint (``[hal.zenoh]
connect`` of the HAL config, or ``--connect``) as a Zenoh client, with ``[hal.zenoh]``'s TLS and identity, and
prints the JSON answer ``{"ok", "state", "error", ...}``.

Exit codes: 0 the action was done; 1 it was refused (the answer says why); 2 nobody answered or bad input.
"""

from __future__ import annotations

import argparse
import json
import sys

from servotau.apps.config_args import HAL, add_config_args, config_files
from servotau.control.operator import ACTIONS
from servotau.errors import HalError, ServotauError

ANSWER_TIMEOUT = 5.0  # [s] wall time to wait for the answer (a reset is applied at the controller's next tick)


def register(sub) -> None:
    p = sub.add_parser("ctl", help="operator commands to a running controller: status, position, torque, start, "
                                   "stop, reset, release",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("action", choices=ACTIONS)
    p.add_argument("task", nargs="?", help="start: the task (a name of config/tasks/, a file or module:attribute)")
    add_config_args(p, HAL)  # [hal.zenoh] robot and connect are the defaults
    p.add_argument("--robot", help="robot name in the keys (default: [hal.zenoh] robot)")
    p.add_argument("--connect", action="append", help="zenoh endpoint of the robot process or a router "
                                                      "(default: [hal.zenoh] connect)")
    p.add_argument("--port", type=int, help="connect to tcp/127.0.0.1:PORT")
    p.add_argument("--robot-side", action="store_true",
                   help="send the action to the robot process (servotau/v1/<robot>/operator), not the controller")
    p.add_argument("--timeout", type=float, default=ANSWER_TIMEOUT, help="[s] wait for the answer")
    p.set_defaults(func=main)


def operator_key(robot: str, robot_side: bool = False) -> str:
    """The operator query's key: the controller's, or the robot's with ``robot_side``."""
    from servotau.hal.wire.protocol import keys

    prefix = keys(robot).prefix
    return f"{prefix}/operator" if robot_side else f"{prefix}/controller/operator"


def send(action: str, *, robot: str, connect: list[str], robot_side: bool = False,
         timeout: float = ANSWER_TIMEOUT, security=None, task: str | None = None) -> dict:
    """Send ``{"action": action}`` (with ``task`` for ``start``) and return the JSON answer (``ok``, ``state``,
    ``error``); ``security``: the
    controller side's TLS and authentication (:class:`~servotau.hal.wire.security.Security`, [hal.zenoh]).

    Raises:
        HalError: Nobody answered within ``timeout`` [s], or the answer is not a JSON object.
    """
    from servotau.hal.wire.session import Session, zenoh_config

    key = operator_key(robot, robot_side)
    who = "robot" if robot_side else "controller"
    session = Session(zenoh_config(connect=connect, mode="client", security=security))  # a peer routes its
    # clients' queries
    try:
        body = {"action": action, **({"task": task} if task is not None else {})}
        replies = list(session.z.get(key, payload=json.dumps(body).encode(), timeout=timeout))
    finally:
        session.close()
    for r in replies:
        if r.ok is None:
            error = r.err.payload.to_bytes().decode(errors="replace")
            raise HalError(f"the {who} answered {key} with an error: {error}")
        try:
            answer = json.loads(r.ok.payload.to_bytes())
        except ValueError as exc:
            raise HalError(f"the {who} answered {key} with no JSON ({exc}): expected {{ok, state, error}}") from None
        if not isinstance(answer, dict) or "ok" not in answer:
            raise HalError(f"the {who} answered {key} with {answer!r}: expected a JSON object with ok, state, error")
        return answer
    hint = ("is the robot process running, with an operator query?" if robot_side else
            "is servotau control running against this robot?")
    raise HalError(f'no {who} of robot "{robot}" answered {key} within {timeout} s via {", ".join(connect)}: {hint}')


def _defaults(args):
    """Robot name, endpoints and security of the controller side ([hal.zenoh] of ``--hal``), as the controller
    connects: with TLS and access control the operator needs an identity whose role may ``operator``."""
    from servotau.hal.config import endpoint_list
    from servotau.hal.registry import hal_section
    from servotau.hal.wire.security import check_endpoints, security_from_section

    z = hal_section(config_files(args, HAL).path(HAL.name)).section("zenoh", {})
    robot = args.robot or z.str("robot", "hrp2")
    security = security_from_section(z, robot_side=False)
    if args.port is not None:
        connect = [f"tcp/127.0.0.1:{args.port}"]
    else:
        connect = args.connect or endpoint_list(z, "connect", ["tcp/127.0.0.1:7447"])
    check_endpoints(security, connect, robot_side=False)
    return robot, connect, security


def main(args) -> int:
    if args.robot_side and args.action != "reset":
        print(f"servotau ctl: --robot-side {args.action}: expected reset (the robot process answers only reset; "
              "its state is on servotau/v1/<robot>/status)", file=sys.stderr)
        return 2
    if (args.action == "start") != (args.task is not None):
        print(f"servotau ctl {args.action}: " + ("expected a task: servotau ctl start TASK" if args.action == "start"
                                                  else f"unexpected argument {args.task!r} (only start takes a task)"),
              file=sys.stderr)
        return 2
    try:
        robot, connect, security = _defaults(args)
        answer = send(args.action, robot=robot, connect=connect, robot_side=args.robot_side, timeout=args.timeout,
                      security=security, task=args.task)
    except ServotauError as exc:  # nobody answered, or a bad [hal.zenoh] (names the field)
        print(f"servotau ctl: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(answer), flush=True)
    if not answer.get("ok"):
        print(f"servotau ctl: {args.action} refused: {answer.get('error')}", file=sys.stderr)
        return 1
    return 0
