"""Robot-side safety, as the robot's firmware has it, shared by the server and the in-process backend.

Per tick, :meth:`Firmware.output` turns the latest accepted command into the desired angles that
reach the servos, or ``None`` once the servos are cut:

- WAITING: no command yet; hold the first measured position (no timeout).
- RUNNING: apply the latest command, clamped to ``[q_min, q_max]`` (rate-limited warning).
- HOLDING: no fresh command for ``hold_after`` [s] (or the controller's liveliness token vanished):
  hold the position measured at that moment. A fresh command resumes RUNNING.
- SERVO_OFF (latched): no fresh command for ``servo_off_after`` [s], or ``|q_des - q| >
  max_position_error`` on any joint (as HRP-2 does), or a non-finite target. Only a restart clears it.

The clock is the caller's: wall time on the server (also while it waits in lock-step), robot time in
the in-process backend (deterministic).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np

from servotau.config import Section, check_settings, load_dataclass, setting

from ..errors import HalError
from ..types import RobotInfo
from ..wire.protocol import FLAG_CLAMPED, FLAG_HOLDING, FLAG_SERVO_OFF, FLAG_WAITING

logger = logging.getLogger(__name__)

LOG_EXTRA = ("hal/state", "hal/wall_time")
"""Extra log columns of the robot side: firmware state (FirmwareState) and time.monotonic() [s]."""


class FirmwareState(IntEnum):
    """Robot-side servo state."""

    WAITING = 0
    RUNNING = 1
    HOLDING = 2
    SERVO_OFF = 3


_STATE_FLAGS = {FirmwareState.WAITING: FLAG_WAITING, FirmwareState.RUNNING: 0,
                FirmwareState.HOLDING: FLAG_HOLDING, FirmwareState.SERVO_OFF: FLAG_SERVO_OFF}


@dataclass(frozen=True)
class SafetyConfig:
    """Watchdog and limits of the robot-side firmware."""

    hold_after: float = setting(0.05, unit="s", min=0, strict_min=True)  # no fresh command: hold the position
    servo_off_after: float = setting(1.0, unit="s", min="hold_after", strict_min=True)  # cut the servos (latched)
    max_position_error: float | None = setting(None, unit="rad", min=0, strict_min=True)  # |q_des - q| trip;
    # None: RobotInfo.max_position_error
    warn_interval: float = setting(1.0, unit="s", min=0)  # minimum wall time between two warnings of one kind
    # Lock-step: the robot waits for each command by design, so only a hung controller should trip the
    # watchdog, not a slow tick (a calibration, a plot flush); a killed one is seen by its liveliness token.
    lockstep_hold_after: float = setting(1.0, unit="s", min=0, strict_min=True)
    lockstep_servo_off_after: float = setting(3.0, unit="s", min="lockstep_hold_after", strict_min=True)

    def __post_init__(self):
        check_settings(self, HalError)

    @classmethod
    def from_section(cls, section: Section) -> SafetyConfig:
        """Read a ``[*.safety]`` table (every field optional)."""
        return load_dataclass(cls, section)

    def for_lockstep(self) -> SafetyConfig:
        """The same settings with the lock-step watchdog times in force."""
        return replace(self, hold_after=self.lockstep_hold_after, servo_off_after=self.lockstep_servo_off_after)


class RateLimitedLog:
    """Log at most one message per ``key`` every ``interval`` seconds of wall time."""

    def __init__(self, log: logging.Logger, interval: float):
        self.log, self.interval = log, interval
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def __call__(self, level: int, key: str, msg: str) -> None:
        now = time.monotonic()
        if now - self._last.get(key, -math.inf) < self.interval:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            return
        n = self._suppressed.pop(key, 0)
        self._last[key] = now
        self.log.log(level, "%s%s", msg, f" ({n} similar messages suppressed)" if n else "")


class Firmware:
    """Command watchdog, joint-limit clamping and position-error trip of one robot."""

    COUNTERS = ("ticks", "commands_accepted", "commands_stale", "commands_rejected",
                "commands_rejected_version", "commands_after_servo_off", "holds", "clamped_ticks")

    def __init__(self, info: RobotInfo, safety: SafetyConfig | None = None):
        self.info = info
        self.safety = safety or SafetyConfig()
        self.max_error = self.safety.max_position_error or info.max_position_error  # [rad]
        self.state = FirmwareState.WAITING
        self.servo_off_reason: str | None = None
        self.counters: dict[str, int] = dict.fromkeys(self.COUNTERS, 0)
        self.clamped = False  # the last output was clamped
        self._q_cmd: np.ndarray | None = None
        self._t_cmd = -math.inf  # time of the last accepted command [s]
        self._q_hold: np.ndarray | None = None
        self._hold_requested = False
        self._warn = RateLimitedLog(logger, self.safety.warn_interval)

    @property
    def last_command_time(self) -> float:
        """When the last command was accepted [s] (caller's clock; -inf before the first)."""
        return self._t_cmd

    @property
    def flags(self) -> int:
        """FLAG_* bits describing the state (sent in the frame header)."""
        return _STATE_FLAGS[self.state] | (FLAG_CLAMPED if self.clamped else 0)

    def accept(self, q_des: np.ndarray, now: float) -> None:
        """Take a validated command (``(nq,)`` finite [rad]) received at ``now`` [s]."""
        if self.state == FirmwareState.SERVO_OFF:
            self.counters["commands_after_servo_off"] += 1
            return
        if self.state == FirmwareState.HOLDING:
            logger.warning("%s: fresh command after a hold: resuming", self.info.name)
        self._q_cmd, self._t_cmd = q_des, now
        self.state = FirmwareState.RUNNING
        self._hold_requested = False
        self.counters["commands_accepted"] += 1

    def reject(self, reason: str, version: bool = False) -> None:
        """Count a malformed command (never applied) and log it at a limited rate."""
        self.counters["commands_rejected"] += 1
        if version:
            self.counters["commands_rejected_version"] += 1
        self._warn(logging.WARNING, "reject", f"{self.info.name}: command rejected: {reason}")

    def stale(self) -> None:
        """Count a valid command that answers an already-stepped frame (not applied)."""
        self.counters["commands_stale"] += 1

    def controller_lost(self) -> None:
        """The controller's liveliness token vanished: hold at the next tick without waiting."""
        if self.state == FirmwareState.RUNNING:
            self._hold_requested = True

    def output(self, q: np.ndarray, now: float) -> np.ndarray | None:
        """Desired angles [rad] for this tick given the measured ``q`` [rad], or None: servos off."""
        self.counters["ticks"] += 1
        self.clamped = False
        st = self.state
        if st == FirmwareState.SERVO_OFF:
            return None
        age = now - self._t_cmd
        if st == FirmwareState.RUNNING and (self._hold_requested or age > self.safety.hold_after):
            why = "controller lost" if self._hold_requested else f"no fresh command for {age * 1e3:.0f} ms"
            logger.warning("%s: %s: holding the measured position", self.info.name, why)
            st = self.state = FirmwareState.HOLDING
            self._q_hold = np.array(q, dtype=float)
            self._hold_requested = False
            self.counters["holds"] += 1
        if st == FirmwareState.HOLDING and age > self.safety.servo_off_after:
            return self._trip(f"no fresh command for {age:.3f} s (servo_off_after = "
                              f"{self.safety.servo_off_after} s)")
        if st == FirmwareState.WAITING and self._q_hold is None:
            self._q_hold = np.array(q, dtype=float)
        target = self._q_cmd if st == FirmwareState.RUNNING else self._q_hold
        out = np.clip(target, self.info.q_min, self.info.q_max)
        if (out != target).any():
            self.clamped = True
            self.counters["clamped_ticks"] += 1
            names = [self.info.joint_names[i] for i in np.flatnonzero(out != target)]
            self._warn(logging.WARNING, "clamp", f"{self.info.name}: command clamped to the joint limits: {names}")
        if not np.isfinite(out).all():
            return self._trip("non-finite target (encoder reading invalid)")
        err = np.abs(out - q)
        if err.max(initial=0.0) > self.max_error:
            i = int(np.argmax(err))
            return self._trip(f'|q_des - q| = {err[i]:.4f} rad on joint "{self.info.joint_names[i]}": '
                              f"expected <= {self.max_error} rad")
        return out

    def _trip(self, reason: str) -> None:
        self.state = FirmwareState.SERVO_OFF
        self.servo_off_reason = reason
        logger.error("%s: SERVO OFF (latched): %s", self.info.name, reason)
        return None

    def status(self) -> dict:
        """State and counters, JSON-ready."""
        return {"state": self.state.name, "servo_off_reason": self.servo_off_reason, **self.counters}
