"""Controller-side interface to a robot: one base class, three backends (zenoh, inprocess, replay).

A controller only sees :class:`Backend`; switching from the simulator to a replay or the real
robot is one line of config (:func:`servotau.hal.registry.open_backend`).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping

import numpy as np

from .errors import HalError
from .types import GroundTruth, RobotInfo, SensorFrame


class JointCommand:
    """Name -> array mapping and validation of desired angles, in one place.

    Holds the full desired-angle vector; :meth:`merge` returns a new vector with some joints set by
    name, or raises :class:`HalError` naming the joint and the expected value (and changes nothing).
    """

    def __init__(self, info: RobotInfo):
        self.info = info
        self._index = {name: i for i, name in enumerate(info.joint_names)}

    def merge(self, base: np.ndarray, q_des: Mapping[str, float]) -> np.ndarray:
        """``base`` with the joints of ``q_des`` [rad] replaced; ``base`` itself is not modified."""
        if not isinstance(q_des, Mapping):
            raise HalError(f"q_des is a {type(q_des).__name__}: expected a mapping joint name -> angle [rad] "
                           "(use write_array for a vector)")
        out = base.copy()
        for name, value in q_des.items():
            i = self._index.get(name)
            if i is None:
                raise HalError(f'joint "{name}" is not a joint of {self.info.name}: expected one of '
                               f"{list(self.info.joint_names)}")
            try:
                v = float(value)
            except (TypeError, ValueError):
                v = math.nan
            if not math.isfinite(v):
                raise HalError(f'q_des["{name}"] = {value!r}: expected a finite angle [rad]')
            out[i] = v
        return out

    def check_array(self, q_des: np.ndarray) -> np.ndarray:
        """A validated float copy of a full desired-angle vector in RobotInfo order."""
        try:
            arr = np.array(q_des, dtype=float)
        except (TypeError, ValueError) as exc:
            raise HalError(f"q_des: expected a vector of {self.info.nq} angles [rad]: {exc}") from None
        if arr.shape != (self.info.nq,):
            raise HalError(f"q_des has shape {arr.shape}: expected ({self.info.nq},) in RobotInfo.joint_names order")
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            i = int(bad[0])
            raise HalError(f'q_des["{self.info.joint_names[i]}"] = {arr[i]}: expected a finite angle [rad]')
        return arr


class Backend(ABC):
    """A robot seen from the controller.

    Protocol of one control tick: ``frame = read()`` then ``write({...})``. In lock-step mode
    :meth:`read` returns the frame of the next tick (the robot steps when it receives the command
    answering the frame last read); in real-time mode the newest frame not yet returned.

    Desired angles are addressed by name; joints not named keep their previous desired angle,
    initially the first measured position. Bad input raises :class:`HalError` and sends nothing.
    """

    info: RobotInfo

    def __init__(self, info: RobotInfo, first_frame: SensorFrame):
        self.info = info
        self._joints = JointCommand(info)
        self._q_des = np.array(first_frame.q, dtype=float)
        self._last_read: SensorFrame | None = None  # last frame returned by read()
        self._answer: SensorFrame = first_frame  # the frame the next write() answers
        self.commands_sent = 0
        self.hold_requested = False  # every command carries the hold flag (set_hold)
        self._closed = False

    # -- reading ------------------------------------------------------------------------------------
    @abstractmethod
    def read(self, timeout: float | None = None) -> SensorFrame:
        """One atomic frame; blocks at most ``timeout`` [s] (None: the backend's default).

        Raises:
            HalTimeoutError: no frame in time.
            HalError: the robot is lost or sent a malformed frame; end of a replayed log.
        """

    def _returned(self, frame: SensorFrame) -> SensorFrame:
        """Bookkeeping of subclasses' read(): ``frame`` is the one the next write answers."""
        self._last_read = self._answer = frame
        return frame

    @property
    def last_frame(self) -> SensorFrame | None:
        """The last frame returned by :meth:`read` (None before the first read)."""
        return self._last_read

    # -- writing ------------------------------------------------------------------------------------
    def write(self, q_des: Mapping[str, float]) -> None:
        """Desired angles [rad] by joint name; the others keep their previous desired angle."""
        self._send_checked(self._joints.merge(self._q_des, q_des))

    def write_array(self, q_des: np.ndarray) -> None:
        """All desired angles [rad] as a vector in ``info.joint_names`` order (fast path)."""
        self._send_checked(self._joints.check_array(q_des))

    def _send_checked(self, q_des: np.ndarray) -> None:
        if self._closed:
            raise HalError(f"{type(self).__name__} of {self.info.name} is closed: expected an open backend")
        self._send(q_des, self._answer)
        self._q_des = q_des
        self.commands_sent += 1

    def set_hold(self, on: bool) -> None:
        """From the next command on, ask the robot to hold (``on``: the controller has tripped) or not: every
        command carries the COMMAND_HOLD flag while it is on, and the robot's firmware brakes and holds from its
        own measurements at once, without waiting for the controller's held q_des to arrive (docs/protocol.md
        "State machine"). The controller sets it on every tick from its latched trip."""
        self.hold_requested = bool(on)

    @abstractmethod
    def _send(self, q_des: np.ndarray, answers: SensorFrame) -> None:
        """Transmit a validated full command answering frame ``answers`` (with the hold flag if
        :attr:`hold_requested`)."""

    @property
    def q_des(self) -> np.ndarray:
        """Copy of the current desired angles [rad] in ``info.joint_names`` order."""
        return self._q_des.copy()

    # -- extras -------------------------------------------------------------------------------------
    def ground_truth(self) -> GroundTruth | None:
        """Latest ground truth (simulation only; for evaluation, never for control)."""
        return None

    def status(self) -> dict:
        """Robot-side state and counters, JSON-ready (content depends on the backend)."""
        return {}

    def close(self) -> None:
        """Release the connection; idempotent."""
        self._closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
