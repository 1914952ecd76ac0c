"""Operator requests to the robot side (``servotau/v1/<robot>/operator``, docs/protocol.md "State machine").

A request is a small JSON object, ``{"action": "reset"}``; the answer is JSON ``{"ok": bool, "state": <firmware
state>, "error": <text or null>}``. ``reset`` clears a latched SERVO_OFF (valid encoders needed): the robot turns
its servos back on and holds the measured position (WAITING) until a controller commands it.
"""

from __future__ import annotations

import json

import numpy as np

from ..types import SensorFrame
from .firmware import Firmware
from .served import ServedRobot

ACTIONS = ("reset",)
MAX_REQUEST_BYTES = 4096


def parse_request(payload: bytes | None) -> tuple[str | None, str | None]:
    """``(action, error)`` of a request payload: exactly one of them is None."""
    if payload is None or not payload:
        return None, 'empty request: expected a JSON object such as {"action": "reset"}'
    if len(payload) > MAX_REQUEST_BYTES:
        return None, f"request of {len(payload)} bytes: expected at most {MAX_REQUEST_BYTES}"
    try:
        d = json.loads(payload)
    except (ValueError, UnicodeDecodeError) as exc:
        return None, f'request is not JSON ({exc}): expected an object such as {{"action": "reset"}}'
    if not isinstance(d, dict) or set(d) != {"action"}:
        return None, f'request {d!r}: expected an object with the single key "action"'
    if d["action"] not in ACTIONS:
        return None, f"action {d['action']!r}: expected one of {list(ACTIONS)}"
    return d["action"], None


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
