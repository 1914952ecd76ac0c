"""Operator actions on the control loop: ``reset`` or ``release`` a latched safety hold, ``status``.

A safety trip does not end the control loop: it holds the last valid measured posture and keeps answering
every frame until an operator acts (:class:`~servotau.control.loop.ControlLoop`). The operator reaches the
loop through an :class:`OperatorChannel`, from any thread (a Zenoh queryable of the controller process,
``servotau ctl``, a test, a script)::

    channel = OperatorChannel()
    threading.Thread(target=loop.run, args=(reference, 3.0), kwargs={"operator": channel}).start()
    channel.request("status")   # OperatorAnswer(ok=True, state='tripped', error=None, report='safety trip ...')
    channel.request("reset")    # refused (ok=False, error says why) while the trip's cause is still there
    channel.request("release")  # the loop ends cleanly

``reset`` and ``release`` are applied by the loop at its next tick (the request waits for that);
``status`` is answered at once from the loop's last published state.

Loop states (:data:`STATES`): ``settling``, ``running``, ``tripped`` (latched hold), ``holding`` (after a
reset: position control at the held posture), ``released``, ``done``.
"""

from __future__ import annotations

import json
import threading
from dataclasses import asdict, dataclass

ACTIONS: tuple[str, ...] = ("reset", "release", "status")
STATES: tuple[str, ...] = ("starting", "settling", "running", "tripped", "holding", "released", "done")


@dataclass(frozen=True)
class OperatorAnswer:
    """The answer to an operator request (the JSON answer of the operator query: ``ok``, ``state``, ``error``)."""

    ok: bool
    state: str  # the loop's state after the action (one of STATES)
    error: str | None = None  # why the action was refused, or None
    report: str | None = None  # the latched trip's message, or None

    def to_json(self) -> bytes:
        return json.dumps(asdict(self)).encode()


def parse_request(payload: bytes | str | None) -> str:
    """The action of a JSON request ``{"action": "reset" | "release" | "status"}``.

    Raises:
        ValueError: Not such a JSON object (the message names the field and the expected values).
    """
    try:
        body = json.loads(payload or b"{}")
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f'request is not JSON ({exc}): expected {{"action": one of {list(ACTIONS)}}}') from None
    action = body.get("action") if isinstance(body, dict) else None
    if action not in ACTIONS:
        raise ValueError(f"action = {action!r}: expected one of {list(ACTIONS)}")
    return action


class _Pending:
    __slots__ = ("action", "answer", "done")

    def __init__(self, action: str):
        self.action = action
        self.answer: OperatorAnswer | None = None
        self.done = threading.Event()


class OperatorChannel:
    """Mailbox between operator requests (any thread) and the control loop (which polls :meth:`take` each tick)."""

    def __init__(self):
        self._lock = threading.RLock()  # reentrant: post() may run in a signal handler of the loop's own thread
        self._pending: list[_Pending] = []
        self._state = "starting"
        self._report: str | None = None
        self.closed = False

    # -- requester side -------------------------------------------------------------------------------
    def request(self, action: str, timeout: float = 2.0) -> OperatorAnswer:
        """Ask the loop for ``action``; wait at most ``timeout`` [s] of wall time for a ``reset`` or ``release``
        to be applied (a refusal if the loop did not take it: it is then withdrawn, never applied later)."""
        if action not in ACTIONS:
            return self._answer(False, f"action = {action!r}: expected one of {list(ACTIONS)}")
        with self._lock:
            if action == "status" or self.closed:
                error = None if action == "status" else f"the control loop has ended ({self._state})"
                return OperatorAnswer(error is None, self._state, error, self._report)
            pending = _Pending(action)
            self._pending.append(pending)
        if pending.done.wait(timeout):
            return pending.answer
        with self._lock:
            if pending in self._pending:
                self._pending.remove(pending)
                return OperatorAnswer(False, self._state, f"the control loop did not take '{action}' within "
                                      f"{timeout} s (is the robot sending frames?)", self._report)
        pending.done.wait()  # taken just now: its answer is on its way
        return pending.answer

    def post(self, action: str) -> None:
        """Queue ``reset`` or ``release`` without waiting for the answer (signal handlers: the loop's own thread)."""
        if action in ("reset", "release"):
            with self._lock:
                if not self.closed:
                    self._pending.append(_Pending(action))

    def handle(self, payload: bytes | str | None, timeout: float = 2.0) -> OperatorAnswer:
        """Answer a JSON request (see :func:`parse_request`); a malformed one is refused, naming the field."""
        try:
            action = parse_request(payload)
        except ValueError as exc:
            return self._answer(False, str(exc))
        return self.request(action, timeout)

    def _answer(self, ok: bool, error: str | None) -> OperatorAnswer:
        with self._lock:
            return OperatorAnswer(ok, self._state, error, self._report)

    # -- loop side ----------------------------------------------------------------------------------
    def publish(self, state: str, report: str | None = None) -> None:
        """The loop's current state (and its latched trip's message)."""
        self._state, self._report = state, report

    def take(self) -> _Pending | None:
        """The oldest pending ``reset`` or ``release`` (loop thread; cheap when there is none)."""
        if not self._pending:
            return None
        with self._lock:
            return self._pending.pop(0) if self._pending else None

    def answer(self, pending: _Pending, ok: bool, state: str, error: str | None = None) -> None:
        """Reply to a taken request (loop thread)."""
        self._state = state
        pending.answer = OperatorAnswer(ok, state, error, self._report)
        pending.done.set()

    def close(self, state: str) -> None:
        """The loop has ended: refuse what is still pending, and every later reset or release."""
        with self._lock:
            self.closed = True
            self._state = state
            pending, self._pending = self._pending, []
        for p in pending:
            p.answer = OperatorAnswer(False, state, f"the control loop has ended ({state})", self._report)
            p.done.set()
