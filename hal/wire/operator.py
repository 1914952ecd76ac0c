"""Operator requests, on the wire: one JSON format for the robot's ``servotau/v1/<robot>/operator`` queryable
(hal/robot/operator.py) and the controller's ``.../controller/operator`` (control/operator.py), docs/protocol.md.

A request is a JSON object ``{"action": NAME, ...}`` of at most :data:`MAX_REQUEST_BYTES`; each side gives its
actions and the keys each action takes besides ``action`` (the robot: ``reset``, none; the controller: ``start``
takes ``task``). No Zenoh here: the controller's library imports it.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence

from ..errors import MalformedMessage

MAX_REQUEST_BYTES = 4096


def parse_request(payload: bytes | str | None, actions: Sequence[str],
                  arguments: Mapping[str, Sequence[str]] | None = None) -> tuple[str, dict]:
    """The action (one of ``actions``) and its other keys (those ``arguments[action]`` allows) of a request.

    Raises:
        MalformedMessage: Empty, too long, not JSON, not an object with ``action``, an unknown action or key; the
            message names the field and the expected value.
    """
    example = f'{{"action": "{actions[0]}"}}'
    if not payload:
        raise MalformedMessage(f"empty request: expected a JSON object such as {example}")
    if len(payload) > MAX_REQUEST_BYTES:
        raise MalformedMessage(f"request of {len(payload)} bytes: expected at most {MAX_REQUEST_BYTES}")
    try:
        body = json.loads(payload)
    except (ValueError, UnicodeDecodeError) as exc:
        raise MalformedMessage(f"request is not JSON ({exc}): expected an object such as {example}") from None
    if not isinstance(body, dict) or "action" not in body:
        raise MalformedMessage(f'request {str(body)[:200]}: expected a JSON object with the key "action"')
    action = body["action"]
    if not isinstance(action, str) or action not in actions:
        raise MalformedMessage(f"action = {action!r}: expected one of {list(actions)}")
    args = {k: v for k, v in body.items() if k != "action"}
    allowed = tuple((arguments or {}).get(action, ()))
    if extra := sorted(set(args) - set(allowed)):
        raise MalformedMessage(f"request keys {extra} with action {action!r}: expected "
                               f"{list(allowed) if allowed else 'no key but action'}")
    return action, args
