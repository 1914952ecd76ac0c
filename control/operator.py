"""Operator actions on the control loop: ``reset`` or ``release`` a latched safety hold, ``status``; switch the
control mode (``position``, ``torque``), ``start`` a task, ``stop`` the run.

A safety trip does not end the control loop: it holds the last valid measured posture and keeps answering
every frame until an operator acts (:class:`~servotau.control.loop.ControlLoop`). The operator reaches the
loop through an :class:`OperatorChannel`, from any thread (a Zenoh queryable of the controller process,
``servotau ctl``, a test, a script)::

    channel = OperatorChannel()
    threading.Thread(target=loop.run, args=(reference, 3.0), kwargs={"operator": channel}).start()
    channel.request("status")   # OperatorAnswer(ok=True, state='tripped', error=None, report='safety trip ...')
    channel.request("reset")    # refused (ok=False, error says why) while the trip's cause is still there
    channel.request("release")  # the loop ends cleanly

Every action but ``status`` is applied by the loop at its next tick (the request waits for that); ``status``
is answered at once from the loop's last published state (and its ``detail``: mode, phase, robot time).
``position``/``torque`` switch the controller's mode bumplessly (refused while a trip is latched); ``stop`` brings
the reference to rest and the controller to position mode, then ends the run (``stopped``); ``start`` takes
``{"action": "start", "task": NAME}`` and replaces the rest of the running task (the loop's ``actions``).

Loop states (:data:`STATES`): ``settling``, ``running``, ``tripped`` (latched hold), ``holding`` (after a
reset: position control at the held posture), ``stopping``, ``released``, ``stopped``, ``done``.
"""

from __future__ import annotations

import json
import threading
from dataclasses import asdict, dataclass

from servotau.hal.errors import MalformedMessage
from servotau.hal.wire.operator import parse_request as _parse

ACTIONS: tuple[str, ...] = ("reset", "release", "status", "position", "torque", "start", "stop")
ARGUMENTS = {"start": ("task",)}  # the keys an action takes besides "action"
STATES: tuple[str, ...] = ("starting", "settling", "running", "tripped", "holding", "stopping", "released", "stopped",
                           "done")


@dataclass(frozen=True)
class OperatorAnswer:
    """The answer to an operator request (the JSON answer of the operator query: ``ok``, ``state``, ``error``)."""

    ok: bool
    state: str  # the loop's state after the action (one of STATES)
    error: str | None = None  # why the action was refused, or None
    report: str | None = None  # the latched trip's message, or None
    detail: dict | None = None  # status: robot time [s], mode, phase (the loop's last published detail)

    def to_json(self) -> bytes:
        return json.dumps(asdict(self)).encode()


def parse_request(payload: bytes | str | None) -> tuple[str, dict]:
    """The action and the arguments of a JSON request ``{"action": one of ACTIONS, ...}`` (``start``: ``task``), in
    the operator format of the robot's own queryable (:func:`servotau.hal.wire.operator.parse_request`).

    Raises:
        MalformedMessage: Not such a JSON object (the message names the field and the expected values).
    """
    action, args = _parse(payload, ACTIONS, ARGUMENTS)
    if action == "start" and not (isinstance(args.get("task"), str) and args["task"]):
        raise MalformedMessage(f"task = {args.get('task')!r}: expected a task name, file or module:attribute with "
                               "start")
    return action, args


class _Pending:
    __slots__ = ("action", "answer", "args", "done")

    def __init__(self, action: str, args: dict | None = None):
        self.action = action
        self.args = args or {}
        self.answer: OperatorAnswer | None = None
        self.done = threading.Event()


class OperatorChannel:
    """Mailbox between operator requests (any thread) and the control loop (which polls :meth:`take` each tick)."""

    def __init__(self):
        self._lock = threading.RLock()  # reentrant: post() may run in a signal handler of the loop's own thread
        self._pending: list[_Pending] = []
        self._state = "starting"
        self._report: str | None = None
        self._detail: dict | None = None
        self.closed = False

    # -- requester side -------------------------------------------------------------------------------
    def request(self, action: str, timeout: float = 2.0, **args) -> OperatorAnswer:
        """Ask the loop for ``action`` (``args``: e.g. ``task`` of ``start``); wait at most ``timeout`` [s] of wall
        time for it to be applied (a refusal if the loop did not take it: it is then withdrawn, never applied
        later)."""
        if action not in ACTIONS:
            return self._answer(False, f"action = {action!r}: expected one of {list(ACTIONS)}")
        with self._lock:
            if action == "status" or self.closed:
                error = None if action == "status" else f"the control loop has ended ({self._state})"
                return OperatorAnswer(error is None, self._state, error, self._report,
                                      self._detail if error is None else None)
            pending = _Pending(action, args)
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
        """Queue ``reset``, ``release`` or ``stop`` without waiting for the answer (signal handlers: the loop's own
        thread)."""
        if action in ("reset", "release", "stop"):
            with self._lock:
                if not self.closed:
                    self._pending.append(_Pending(action))

    def handle(self, payload: bytes | str | None, timeout: float = 2.0) -> OperatorAnswer:
        """Answer a JSON request (see :func:`parse_request`); a malformed one is refused, naming the field."""
        try:
            action, args = parse_request(payload)
        except MalformedMessage as exc:
            return self._answer(False, str(exc))
        return self.request(action, timeout, **args)

    def _answer(self, ok: bool, error: str | None) -> OperatorAnswer:
        with self._lock:
            return OperatorAnswer(ok, self._state, error, self._report)

    # -- loop side ----------------------------------------------------------------------------------
    def publish(self, state: str, report: str | None = None, detail: dict | None = None) -> None:
        """The loop's current state (and its latched trip's message; ``detail``: time, mode, phase for status)."""
        self._state, self._report = state, report
        if detail is not None:
            self._detail = detail

    def take(self) -> _Pending | None:
        """The oldest pending request (loop thread; cheap when there is none)."""
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
        """The loop has ended: refuse what is still pending, and every later request but status."""
        with self._lock:
            self.closed = True
            self._state = state
            pending, self._pending = self._pending, []
        for p in pending:
            p.answer = OperatorAnswer(False, state, f"the control loop has ended ({state})", self._report)
            p.done.set()
