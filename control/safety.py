"""Safety checks run on every tick; the first failing check names itself, the joint and the value vs the limit.

Checks (names in :data:`CHECKS`):

- ``sensor_status``   a sensor of the frame is not OK (``frame.status`` nonzero: stale, invalid, saturated)
- ``stale_frame``     the frame's robot time did not advance
- ``invalid_frame``   NaN or inf in the encoders, the IMU or the F/T wrenches
- ``joint_limit``     a measured angle is outside ``[q_min + margin, q_max - margin]``
- ``invalid_estimate`` NaN or inf in the estimate (q, dq, ddq, tau), or no valid estimate in torque mode
- ``estimate_gap``    torque mode after more skipped frames than the estimator's ``max_gap``: the estimate is
                      finite but invalid for ``value`` more ticks (until a window of real readings)
- ``joint_velocity``  ``|dq_hat| > max_velocity``
- ``joint_torque``    ``|tau_hat| > max_torque``
- ``command_error``   ``|q_des - q| > max_command_error`` (or a non-finite command)

The monitor only reports; :class:`~servotau.control.manager.ControlManager` latches the trip.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from servotau.errors import ControlError, SafetyTrip
from servotau.hal.types import FT_SENSOR_NAMES, STATUS_NAMES, RobotInfo, SensorFrame

from .config import SafetyLimits

CHECKS: tuple[str, ...] = (
    "sensor_status",
    "stale_frame",
    "invalid_frame",
    "joint_limit",
    "invalid_estimate",
    "estimate_gap",
    "joint_velocity",
    "joint_torque",
    "command_error",
    "robot_servo_off",
)

_UNITS = {"joint_limit": "rad", "joint_velocity": "rad/s", "joint_torque": "N m", "command_error": "rad",
          "stale_frame": "s"}


@dataclass(frozen=True)
class SafetyReport:
    """Why the controller tripped: the check, the joint (or sensor) and the value against the limit."""

    check: str  # one of CHECKS
    where: str  # joint or sensor name ("" if not applicable)
    value: float  # offending value
    limit: float  # the limit it violated
    time: float  # [s] robot time of the frame
    seq: int  # frame sequence number

    @property
    def message(self) -> str:
        unit = _UNITS.get(self.check, "")
        unit = f" {unit}" if unit else ""
        where = f" {self.where}" if self.where else ""
        what = {
            "sensor_status": f"status = {self.value:g} (expected 0 = OK)",
            "stale_frame": f"time = {self.value:.6f} s, expected > previous {self.limit:.6f} s",
            "invalid_frame": "value is NaN or inf, expected finite",
            "invalid_estimate": "value is NaN or inf, expected finite",
            "estimate_gap": f"frames were skipped for longer than max_gap: the estimate is invalid for "
                            f"{self.value:g} more ticks",
            "joint_limit": f"q = {self.value:.4f}{unit} beyond the limit with margin {self.limit:.4f}{unit}",
            "robot_servo_off": "the robot cut its servos (a robot-side trip: `servotau ctl reset --robot-side` once "
                               "its cause is gone)",
        }.get(self.check, f"|value| = {abs(self.value):.4g}{unit} > limit {self.limit:.4g}{unit}")
        return f"safety trip [{self.check}]{where}: {what} at t = {self.time:.3f} s (seq {self.seq})"

    def error(self) -> SafetyTrip:
        """The exception an application raises if it wants the trip to stop it."""
        return SafetyTrip(self.message)


class SafetyMonitor:
    """Vectorised checks against :class:`SafetyLimits`, without allocation when nothing trips.

    Hot-path tricks: a NaN or inf anywhere in ``x`` makes ``dot(x, x)`` non-finite (one call instead of
    ``isfinite(x).all()``), and ``argmax`` of ``|x| / limit`` finds the worst joint (NaN included) in one pass.
    """

    def __init__(self, info: RobotInfo, limits: SafetyLimits):
        n = info.nq
        if limits.max_torque.size != n:
            raise ControlError(f"limits are for {limits.max_torque.size} joints: expected {n}")
        self.joint_names = info.joint_names
        self.limits = limits
        self.q_low = info.q_min + limits.joint_limit_margin
        self.q_high = info.q_max - limits.joint_limit_margin
        self._inv = {name: 1.0 / getattr(limits, name) for name in ("max_command_error", "max_torque", "max_velocity")}
        self.last_time = -np.inf
        self._a = np.zeros(n)
        self._b = np.zeros(n)

    def reset(self) -> None:
        """Forget the last frame time (after a reconnection)."""
        self.last_time = -np.inf

    def _report(self, check: str, i: int, value: float, limit: float, frame: SensorFrame,
                where: str | None = None) -> SafetyReport:
        return SafetyReport(check, self.joint_names[i] if where is None else where, float(value), float(limit),
                            float(frame.time), int(frame.seq))

    def check_frame(self, frame: SensorFrame) -> SafetyReport | None:
        """Status, time and finiteness of the raw frame, then joint limits on the encoders."""
        status = frame.status
        if np.count_nonzero(status):
            i = int(np.flatnonzero(status)[0])
            return self._report("sensor_status", 0, status[i], 0, frame, STATUS_NAMES[i])
        last = self.last_time
        if not frame.time > last:  # also catches a NaN time
            return self._report("stale_frame", 0, frame.time, last, frame, "")
        self.last_time = float(frame.time)
        q = frame.q
        if not math.isfinite(np.dot(q, q)):
            i = int(np.flatnonzero(~np.isfinite(q))[0])
            return self._report("invalid_frame", i, q[i], 0, frame)
        gyro, acc = frame.imu_angular_velocity, frame.imu_linear_acceleration
        if not math.isfinite(np.dot(gyro, gyro) + np.dot(acc, acc)):
            return self._report("invalid_frame", 0, np.nan, 0, frame, "imu")
        w = frame.wrenches
        if not math.isfinite(np.vdot(w, w)):
            row = int(np.flatnonzero(~np.isfinite(w).all(axis=1))[0])
            return self._report("invalid_frame", 0, np.nan, 0, frame, FT_SENSOR_NAMES[row])
        a, b = self._a, self._b
        np.subtract(q, self.q_low, out=a)  # >= 0 inside
        np.subtract(self.q_high, q, out=b)  # >= 0 inside
        np.minimum(a, b, out=a)
        i = int(a.argmin())
        if a[i] < 0:
            limit = self.q_low[i] if q[i] < self.q_low[i] else self.q_high[i]
            return self._report("joint_limit", i, q[i], limit, frame)
        return None

    def _worst(self, x: np.ndarray, limit: str) -> int:
        """Index of the worst |x| / limit if it exceeds 1 (or is NaN), else -1."""
        a = self._a
        np.abs(x, out=a)
        a *= self._inv[limit]
        i = int(a.argmax())  # NaN wins argmax
        return -1 if a[i] <= 1.0 else i

    def check_estimate(self, frame: SensorFrame, q, dq, ddq, tau) -> SafetyReport | None:
        """Finite estimate, joint velocities and estimated torques within their limits."""
        for x in (q, ddq):
            if not math.isfinite(np.dot(x, x)):
                i = int(np.flatnonzero(~np.isfinite(x))[0])
                return self._report("invalid_estimate", i, x[i], 0, frame)
        for x, check, limit in ((dq, "joint_velocity", "max_velocity"), (tau, "joint_torque", "max_torque")):
            i = self._worst(x, limit)
            if i >= 0:
                if not math.isfinite(x[i]):
                    return self._report("invalid_estimate", i, x[i], 0, frame)
                return self._report(check, i, x[i], getattr(self.limits, limit)[i], frame)
        return None

    def check_command(self, frame: SensorFrame, dq_err: np.ndarray) -> SafetyReport | None:
        """``|q_des - q|`` within ``max_command_error`` and finite."""
        i = self._worst(dq_err, "max_command_error")
        if i >= 0:
            return self._report("command_error", i, dq_err[i], self.limits.max_command_error[i], frame)
        return None
