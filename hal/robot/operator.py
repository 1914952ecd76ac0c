"""Operator requests to the robot side (``servotau/v1/<robot>/operator``, docs/protocol.md "State machine").

A request is a small JSON object, ``{"action": "reset"}``; the answer is JSON ``{"ok": bool, "state": <firmware
state>, "error": <text or null>}``. ``reset`` clears a latched SERVO_OFF (valid encoders needed): the robot turns
its servos back on and holds the measured position (WAITING) until a controller commands it.
"""

from __future__ import annotations

import json

import numpy as np

from ..errors import MalformedMessage
from ..types import SensorFrame
from ..wire.operator import parse_request as _parse
from .firmware import Firmware
from .served import ServedRobot

ACTIONS = ("reset",)


def parse_request(payload: bytes | None) -> tuple[str | None, str | None]:
    """``(action, error)`` of a request payload (hal/wire/operator.py): exactly one of them is None."""
    try:
        return _parse(payload, ACTIONS)[0], None
    except MalformedMessage as exc:
        return None, str(exc)


def reset(firmware: Firmware, robot: ServedRobot, frame: SensorFrame) -> tuple[bool, str | None]:
    """Reset ``firmware`` from the current ``frame`` and turn the servos of ``robot`` back on if it was latched
    off. A robot without ``servo_on()`` cannot be reset without a restart."""
    was_off = firmware.state.name == "SERVO_OFF"
    servo_on = getattr(robot, "servo_on", None)
    if was_off and servo_on is None:
        return False, f"{type(robot).__name__} has no servo_on(): restart the robot process to reset it"
    ok, error = firmware.reset(np.asarray(frame.q), int(frame.status[0]))
    if ok and was_off:
        servo_on()
    return ok, error


def answer(firmware: Firmware, robot: ServedRobot, frame: SensorFrame, payload: bytes | None) -> tuple[str, bool]:
    """The JSON answer to a request, and whether a reset happened (the caller republishes its state)."""
    action, error = parse_request(payload)
    ok, did = False, False
    if action == "reset":
        before = firmware.counters["resets"]
        ok, error = reset(firmware, robot, frame)
        did = firmware.counters["resets"] > before
    return json.dumps({"ok": ok, "state": firmware.state.name, "error": error}), did
