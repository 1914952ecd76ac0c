"""Robot-side safety, as the robot's firmware has it, shared by the server and the in-process backend.

Per tick, :meth:`Firmware.output` turns the latest accepted command into the desired angles that reach
the servos, or ``None`` once the servos are cut. States (``FLAG_*`` in every frame, ``state`` on
``.../status``):

- WAITING: no command yet (or since a reset); hold the measured position, no timeout.
- RUNNING: apply the latest command, clamped to ``[q_min, q_max]`` and bounded by the per-joint
  ``max_velocity`` / ``max_acceleration`` of ``q_des`` (``limit_action = "clamp"``: the bounded value is
  applied, FLAG_RATE_LIMITED; ``"trip"``: HOLDING).
- HOLDING: hold a position, indefinitely while the encoders are valid, entered when
  no fresh command came for ``hold_after`` [s] (``lockstep_hold_after`` in lock-step) or the claim ended
  (the claimer's session closed or it released: ``hold_reason``), a command broke a rate limit with
  ``limit_action = "trip"``, a command carried COMMAND_HOLD (the controller tripped: :attr:`hold_commanded`,
  held from the measured posture of the frame that command answers), or the encoders went invalid or stale
  (FLAG_SENSOR_FAULT: hold their last valid reading, per joint; commands are not applied). A hold caught moving
  brakes for ``hold_brake_time`` (``q_hold - hold_damping * dq``, the firmware's own encoders; not after an encoder
  fault) and is never rate limited. A fresh command without COMMAND_HOLD resumes RUNNING (once the encoders are
  valid again); commands with it keep the hold and the watchdog fed. In lock-step the server holds for a hung
  controller without stepping (:meth:`watchdog`; simulated time stands still).
- SERVO_OFF (latched) on robot-side faults only: ``|q_des - q| > max_position_error`` on a valid joint (as
  HRP-2 does), encoders invalid for more than ``invalid_encoders_after`` [s] of robot time (ticks x period),
  no valid encoder reading ever, or (if set) no fresh command for ``servo_off_after``. :meth:`reset` (the
  operator's request, never a command) clears it with valid encoders: WAITING, servos on, holding the
  measured position.

Transitions, in short (docs/protocol.md "State machine")::

    WAITING --command--> RUNNING --watchdog / controller lost / rate trip / COMMAND_HOLD / encoders--> HOLDING
    HOLDING --fresh command without COMMAND_HOLD, encoders valid--> RUNNING
    any --position error / encoders invalid too long--> SERVO_OFF --operator reset--> WAITING

Commands reach :meth:`accept` only once decoded (hal/wire/protocol.py) and admitted by
:class:`~.gate.CommandGate`; :meth:`reject` and :meth:`stale` count the others, by reason.

The clock is the caller's: wall time on the server (also while it waits in lock-step), robot time in
the in-process backend (deterministic). The rate limits and the encoder-fault time count robot ticks (one
period each).
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from enum import IntEnum

import numpy as np

from ..types import STATUS_INVALID, STATUS_OK, STATUS_SATURATED, RobotInfo, SensorFrame
from ..wire.protocol import (
    FLAG_CLAMPED,
    FLAG_HOLDING,
    FLAG_RATE_LIMITED,
    FLAG_SENSOR_FAULT,
    FLAG_SERVO_OFF,
    FLAG_WAITING,
)
from .gate import REJECT_REASONS
from .limits import RateLimiter
from .safety import JointRateLimits, RateLimitedLog, SafetyConfig

__all__ = ["LOG_EXTRA", "Firmware", "FirmwareState", "JointRateLimits", "RateLimitedLog", "SafetyConfig",
           "checked_frame"]

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
_VALID = (STATUS_OK, STATUS_SATURATED)  # encoder status whose finite readings are measurements


def checked_frame(frame: SensorFrame) -> SensorFrame:
    """``frame`` with every sensor group holding a NaN or inf marked INVALID (a status OK with a non-finite
    value would make the frame undecodable, docs/protocol.md)."""
    groups = [frame.q, np.concatenate((frame.imu_angular_velocity, frame.imu_linear_acceleration)),
              *frame.wrenches]
    bad = [k for k, g in enumerate(groups) if frame.status[k] == STATUS_OK and not np.isfinite(g).all()]
    if not bad:
        return frame
    status = np.array(frame.status, dtype=np.uint8)
    status[bad] = STATUS_INVALID
    status.setflags(write=False)
    return replace(frame, status=status)


class Firmware:
    """Command watchdog, joint-limit clamping, rate limits, sensor checks and trips of one robot."""

    COUNTERS = ("ticks", "commands_accepted", "commands_stale", "commands_rejected", "commands_rejected_version",
                "commands_after_servo_off", "commands_during_sensor_fault", "holds", "clamped_ticks",
                "rate_limited_ticks", "rate_limit_trips", "sensor_fault_ticks", "trips", "resets", "hold_commands")

    def __init__(self, info: RobotInfo, safety: SafetyConfig | None = None):
        self.info = info
        self.safety = safety or SafetyConfig()
        self.max_error = self.safety.max_position_error or info.max_position_error  # [rad]
        self.limiter = RateLimiter(*self.safety.rate_limits(info), info.period)
        self.state = FirmwareState.WAITING
        self.servo_off_reason: str | None = None  # why the servos are off (None unless SERVO_OFF)
        self.trip_reason: str | None = None  # the last servo-off trip's reason (kept after a reset)
        self.hold_reason: str | None = None  # why the current (or last) hold started
        self.counters: dict[str, int] = dict.fromkeys(self.COUNTERS, 0)
        self.rejected: dict[str, int] = dict.fromkeys(REJECT_REASONS, 0)  # rejected commands by reason
        self.clamped = False  # the last output was clamped to the joint limits
        self.rate_limited = False  # the last output was bounded by the rate limits
        self.sensor_fault = False  # the encoders are invalid or stale
        self._fault_ticks = 0  # ticks since they went so
        self._q_valid: np.ndarray | None = None  # last valid reading of each joint [rad] (NaN: never valid)
        self._q_cmd: np.ndarray | None = None
        self._t_cmd = -math.inf  # time of the last accepted command [s]
        self._q_hold: np.ndarray | None = None
        self._hold_requested = False
        self.hold_commanded = False  # holding because the claimer's commands carry COMMAND_HOLD
        self._hold_age: int | None = None  # a commanded hold starts at the next tick, from this many ticks ago
        self._brake_ticks: int | None = None  # ticks the hold has braked so far (None: not braking)
        n = info.nq
        self._history = np.full((self.safety.max_command_age_ticks + 2, n), np.nan)  # last valid readings [rad]
        self._n_history = 0  # readings pushed so far
        self._q_prev = np.full(n, np.nan)  # the previous tick's encoders [rad] (NaN: invalid)
        self._dq = np.zeros(n)  # [rad/s] their backward difference, within +-max_velocity (0: unknown)
        self._warn = RateLimitedLog(logger, self.safety.warn_interval)

    # -- inputs ------------------------------------------------------------------------------------
    @property
    def last_command_time(self) -> float:
        """When the last command was accepted [s] (caller's clock; -inf before the first)."""
        return self._t_cmd

    @property
    def flags(self) -> int:
        """FLAG_* bits describing the state (sent in the frame header)."""
        return (_STATE_FLAGS[self.state] | (FLAG_CLAMPED if self.clamped else 0)
                | (FLAG_RATE_LIMITED if self.rate_limited else 0) | (FLAG_SENSOR_FAULT if self.sensor_fault else 0))

    def accept(self, q_des: np.ndarray, now: float, hold: bool = False, age: int = 0) -> None:
        """Take an admitted command (``(nq,)`` finite [rad]) received at ``now`` [s]. ``hold``: it carries
        COMMAND_HOLD: hold from the next tick on (``q_des`` is not applied), from the measured posture of the frame
        it answers, ``age`` ticks older than the newest (the command's latency)."""
        if self.state == FirmwareState.SERVO_OFF:
            self.counters["commands_after_servo_off"] += 1
            return
        if self.sensor_fault:  # holding the last valid reading until the encoders are valid again
            self.counters["commands_during_sensor_fault"] += 1
            return
        self._t_cmd = now
        self._hold_requested = False
        self.counters["commands_accepted"] += 1
        if hold:
            self.counters["hold_commands"] += 1
            if not self.hold_commanded:
                self.hold_commanded = True
                if self.state != FirmwareState.HOLDING:  # else keep the hold in force (and its posture)
                    self._hold_age = max(int(age), 0)
            return
        if self.state == FirmwareState.HOLDING:
            logger.warning("%s: fresh command after a hold: resuming", self.info.name)
        self._q_cmd = q_des
        self.state = FirmwareState.RUNNING
        self.hold_commanded, self._hold_age = False, None

    def reject(self, reason: str, message: str = "") -> None:
        """Count a command that is never applied, by ``reason`` (:data:`~.gate.REJECT_REASONS`), and log it
        at a limited rate."""
        self.counters["commands_rejected"] += 1
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        if reason == "version":
            self.counters["commands_rejected_version"] += 1
        self._warn(logging.WARNING, "reject", f"{self.info.name}: command rejected ({reason}): {message or reason}")

    def stale(self) -> None:
        """Count a valid command that answers an older frame (not applied, the watchdog not re-armed)."""
        self.counters["commands_stale"] += 1

    def controller_lost(self) -> None:
        """The claim ended (the claimer's session closed, or it released): hold at the next tick without waiting
        (a commanded hold goes on, no longer commanded)."""
        if self.state == FirmwareState.RUNNING:
            self._hold_requested = True
        self.hold_commanded = False

    # -- the tick ----------------------------------------------------------------------------------
    def last_valid(self, q: np.ndarray) -> np.ndarray:
        """``q`` [rad] with each invalid joint replaced by its last valid reading (0 if never valid): a finite
        position for a robot whose servos are off."""
        if self._q_valid is None:
            return np.nan_to_num(np.asarray(q, dtype=float), nan=0.0, posinf=0.0, neginf=0.0)
        out = np.where(np.isfinite(q), q, self._q_valid)
        return np.nan_to_num(out, nan=0.0)

    def output(self, q: np.ndarray, now: float, encoders: int = STATUS_OK) -> np.ndarray | None:
        """Desired angles [rad] for this tick given the measured ``q`` [rad] and the encoders' status byte,
        or None: servos off."""
        self.counters["ticks"] += 1
        self.clamped = self.rate_limited = False
        valid = np.isfinite(q) & (encoders in _VALID)
        if self._q_valid is None:
            self._q_valid = np.where(valid, q, np.nan)
        else:
            self._q_valid[valid] = q[valid]
        self._measure(q, valid)
        if self._sensors(valid.all()) or self.state == FirmwareState.SERVO_OFF:
            return None
        if self._hold_age is not None:  # a commanded hold begins
            if self.sensor_fault:  # in the tick the encoders failed: the fault's plain hold stands, unbraked
                self.hold_reason = f"{self.hold_reason}; the controller tripped (COMMAND_HOLD)"
            else:
                self._hold("the controller tripped (COMMAND_HOLD)", self._hold_age)
            self._hold_age = None
        age = now - self._t_cmd
        if not self.watchdog(now) and self.state != FirmwareState.RUNNING and self._q_hold is None:
            self._q_hold = self._q_valid.copy()
        if self.servo_off_due(now):
            return self._trip(f"no fresh command for {age:.3f} s (servo_off_after = {self.safety.servo_off_after} s)")
        running = self.state == FirmwareState.RUNNING
        target = self._q_cmd if running else self._hold_target()
        if not np.isfinite(target).all():
            return self._trip("no valid encoder reading to hold")
        out = np.clip(target, self.info.q_min, self.info.q_max)
        if (out != target).any():
            self.clamped = True
            self.counters["clamped_ticks"] += 1
            names = [self.info.joint_names[i] for i in np.flatnonzero(out != target)]
            self._warn(logging.WARNING, "clamp", f"{self.info.name}: command clamped to the joint limits: {names}")
        if running:
            out = self._rate_limit(out, np.where(valid, q, np.nan))
        if self.state == FirmwareState.RUNNING:
            self.limiter.applied(out)
        else:
            self.limiter.reset(out)
        err = np.where(valid, np.abs(out - q), 0.0)
        if err.max(initial=0.0) > self.max_error:
            i = int(np.argmax(err))
            return self._trip(f'|q_des - q| = {err[i]:.4f} rad on joint "{self.info.joint_names[i]}": '
                              f"expected <= {self.max_error} rad")
        return out

    def servo_off_due(self, now: float) -> bool:
        """HOLDING without a fresh command for longer than ``servo_off_after`` (if set) at ``now`` [s]: the next
        :meth:`output` cuts the servos."""
        off_after = self.safety.servo_off_after
        return self.state == FirmwareState.HOLDING and off_after is not None and now - self._t_cmd > off_after

    def watchdog(self, now: float) -> bool:
        """RUNNING without a fresh command for ``hold_after`` at ``now`` [s] (or with the controller lost):
        hold the last valid reading from now on. True if a hold began (also run by :meth:`output`)."""
        age = now - self._t_cmd
        if self.hold_commanded and age > self.safety.hold_after:  # the holding controller went silent
            self.hold_commanded = False
            self.hold_reason = f"{self.hold_reason}; then no fresh command for {age * 1e3:.0f} ms"
        if self.state != FirmwareState.RUNNING or not (self._hold_requested or age > self.safety.hold_after):
            return False
        self._hold("controller lost" if self._hold_requested else f"no fresh command for {age * 1e3:.0f} ms")
        return True

    def _sensors(self, all_valid: bool) -> bool:
        """Track an encoder fault; True if it cuts the servos now."""
        if all_valid:
            if self.sensor_fault:
                self.sensor_fault = False
                logger.warning("%s: encoders valid again after %.0f ms: holding until a fresh command",
                               self.info.name, self._fault_ticks * self.info.period * 1e3)
            return False
        self.counters["sensor_fault_ticks"] += 1
        if self.state == FirmwareState.SERVO_OFF:
            return False
        if not self.sensor_fault:
            self.sensor_fault, self._fault_ticks = True, 0
            if self.state == FirmwareState.RUNNING or self._q_hold is None:
                self._hold("encoders invalid or stale", brake=False)
            else:
                self.hold_reason = "encoders invalid or stale"
        self._fault_ticks += 1
        invalid = self._fault_ticks * self.info.period  # [s] of robot time, whatever the wall clock does
        if invalid > self.safety.invalid_encoders_after + 1e-9:
            self._trip(f"encoders invalid or stale for {invalid * 1e3:.0f} ms of robot time "
                       f"(invalid_encoders_after = {self.safety.invalid_encoders_after} s)")
            return True
        return False

    def _hold(self, why: str, age: int = 0, brake: bool = True) -> None:
        """Hold the last valid reading of each joint from this tick on (``age`` > 0: the valid reading of ``age``
        ticks ago, within a quarter of ``max_position_error`` of the last one), braking unless ``brake`` is False."""
        if self.state == FirmwareState.RUNNING or (self.state == FirmwareState.WAITING and self.hold_commanded):
            logger.warning("%s: %s: holding the measured position", self.info.name, why)
            self.state = FirmwareState.HOLDING
            self.counters["holds"] += 1
        self.hold_reason = why
        self._q_hold = None if self._q_valid is None else self._q_valid.copy()
        if self._q_hold is not None and 0 < age < min(self._n_history, len(self._history)):
            past = self._history[(self._n_history - 1 - age) % len(self._history)]
            m = 0.25 * self.max_error
            self._q_hold += np.where(np.isfinite(past), np.clip(past - self._q_hold, -m, m), 0.0)
        self._brake_ticks = 0 if brake and self.safety.hold_damping > 0.0 else None
        self._hold_requested = False

    def _measure(self, q: np.ndarray, valid: np.ndarray) -> None:
        """Record this tick's valid readings (history) and the encoders' velocity (backward difference)."""
        self._history[self._n_history % len(self._history)] = self._q_valid
        self._n_history += 1
        np.subtract(q, self._q_prev, out=self._dq)
        self._dq /= self.info.period
        self._dq[~(valid & np.isfinite(self._dq))] = 0.0
        np.clip(self._dq, -self.limiter.v_max, self.limiter.v_max, out=self._dq)
        self._q_prev[:] = np.where(valid, q, np.nan)

    def _hold_target(self) -> np.ndarray | None:
        """This tick's hold: ``q_hold - hold_damping * w * dq`` while braking (``w`` a half-cosine from 1 to 0 over
        ``hold_brake_time`` of robot time; the term within a quarter of ``max_position_error``), then ``q_hold``."""
        k, s = self._brake_ticks, self.safety
        if k is None or self._q_hold is None:
            return self._q_hold
        elapsed = k * self.info.period
        if elapsed >= s.hold_brake_time:
            self._brake_ticks = None
            return self._q_hold
        self._brake_ticks = k + 1
        w = 0.5 * (1.0 + math.cos(math.pi * elapsed / s.hold_brake_time))
        m = 0.25 * self.max_error
        return self._q_hold - np.clip(s.hold_damping * w * self._dq, -m, m)

    def _rate_limit(self, out: np.ndarray, q: np.ndarray) -> np.ndarray:
        if self.limiter.q is None:  # the first command ever: from the measured position, at rest
            self.limiter.reset(self._q_valid)
        bounded = self.limiter.bound(out, q)
        over = np.abs(bounded - out) > 1e-9
        if not over.any():
            return out
        names = [self.info.joint_names[i] for i in np.flatnonzero(over)]
        if self.safety.limit_action == "clamp":
            self.rate_limited = True
            self.counters["rate_limited_ticks"] += 1
            self._warn(logging.WARNING, "rate", f"{self.info.name}: command bounded by the velocity/acceleration "
                                                f"limits: {names}")
            return bounded
        self.counters["rate_limit_trips"] += 1
        self._hold(f"command beyond the velocity/acceleration limits on {names}")
        return self._q_hold

    def _trip(self, reason: str) -> None:
        self.state = FirmwareState.SERVO_OFF
        self.servo_off_reason = self.trip_reason = reason
        self.counters["trips"] += 1
        logger.error("%s: SERVO OFF (latched): %s", self.info.name, reason)
        return None

    # -- operator ----------------------------------------------------------------------------------
    def reset(self, q: np.ndarray, encoders: int = STATUS_OK) -> tuple[bool, str | None]:
        """The operator's reset with the current reading ``q`` [rad]: a latched SERVO_OFF becomes WAITING,
        holding ``q`` (the caller turns the servos back on). ``(ok, error)``; nothing to do is ok."""
        if self.state != FirmwareState.SERVO_OFF:
            return True, None
        bad = ~np.isfinite(q) | (encoders not in _VALID)
        if bad.any():
            names = [self.info.joint_names[i] for i in np.flatnonzero(bad)]
            return False, f"encoders invalid or stale on {names}: expected valid readings before a reset"
        q = np.array(q, dtype=float)
        self.state = FirmwareState.WAITING
        self.servo_off_reason, self.sensor_fault, self._hold_requested = None, False, False
        self.hold_commanded, self._hold_age, self._brake_ticks = False, None, None
        self._q_valid, self._q_hold, self._q_cmd, self._t_cmd = q.copy(), q, None, -math.inf
        self.limiter.reset(q)
        self.counters["resets"] += 1
        logger.warning("%s: reset by the operator: servos on, holding the measured position", self.info.name)
        return True, None

    def status(self) -> dict:
        """State, reasons and counters, JSON-ready."""
        return {"state": self.state.name, "servo_off_reason": self.servo_off_reason, "trip_reason": self.trip_reason,
                "hold_reason": self.hold_reason, "hold_commanded": self.hold_commanded,
                "sensor_fault": self.sensor_fault,
                "rejected": dict(self.rejected), "commands_not_claimer": self.rejected["not_claimer"], **self.counters}
