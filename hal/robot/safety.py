"""Settings of the robot-side firmware: ``[hal.safety]`` (:class:`SafetyConfig`) and its per-joint
overrides ``[hal.safety.joints.<joint>]`` (:class:`JointRateLimits`).

Where the defaults come from:

- ``max_position_error``: ``RobotInfo.max_position_error`` (HRP-2: 0.1 rad, the threshold of the paper's
  experiments, /work/shared/hrp2-public-figures.md "The low-level servo").
- ``max_velocity`` 5 rad/s: no joint velocity limit of HRP-2 is public (hrp2-public-figures.md lists position
  limits only); the controller's own bound on ``|dq_hat|`` (config/control.toml ``[safety] max_velocity``).
- ``max_acceleration`` 2000 rad/s^2: no public figure either; about twice the largest acceleration of ``q_des``
  in the shipped torque-mode swing (``servotau control --backend inprocess --mode torque``: 1054 rad/s^2 on
  RLEG_JOINT2, one-tick steps of the friction compensation), so that a normal run is never bounded.
- joint position limits: ``RobotInfo.q_min`` / ``q_max`` (the robot description).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from servotau.config import Section, check_settings, load_dataclass, setting

from ..errors import HalError
from ..types import RobotInfo
from .gate import HISTORY

LIMIT_ACTIONS = ("clamp", "trip")
"""What the firmware does with a command beyond the velocity or acceleration limit: apply the bounded
value, or hold the measured position."""


@dataclass(frozen=True)
class JointRateLimits:
    """Per-joint overrides of the rate limits (``None``: the value of ``[hal.safety]``)."""

    max_velocity: float | None = setting(None, unit="rad/s", min=0, strict_min=True)
    max_acceleration: float | None = setting(None, unit="rad/s^2", min=0, strict_min=True)

    def __post_init__(self):
        check_settings(self, HalError)


@dataclass(frozen=True)
class SafetyConfig:
    """Watchdog, limits and command checks of the robot-side firmware (see :mod:`.firmware`)."""

    hold_after: float = setting(0.035, unit="s", min=0, strict_min=True)  # no fresh command: hold the position
    servo_off_after: float | None = setting(None, unit="s", min="hold_after", strict_min=True)  # no fresh command
    # for this long: servo off (latched); None: hold indefinitely (a missing controller is not a robot fault)
    max_position_error: float | None = setting(None, unit="rad", min=0, strict_min=True)  # |q_des - q| trip;
    # None: RobotInfo.max_position_error
    max_velocity: float = setting(5.0, unit="rad/s", min=0, strict_min=True)  # |q_des[k] - q_des[k-1]| / period
    max_acceleration: float = setting(2000.0, unit="rad/s^2", min=0, strict_min=True)  # of q_des, tick to tick
    limit_action: str = setting("clamp", choices=LIMIT_ACTIONS)  # beyond max_velocity / max_acceleration
    joints: tuple[tuple[str, JointRateLimits], ...] = ()  # per-joint overrides ([hal.safety.joints.<joint>])
    max_command_age_ticks: int = setting(20, min=0, max=HISTORY - 1)  # realtime: a command answering a frame
    # more ticks older than the newest is rejected
    invalid_encoders_after: float = setting(0.2, unit="s", min=0, strict_min=True)  # encoders invalid or stale
    # this long of robot time (ticks x period): servo off (latched); shorter: hold their last valid reading
    warn_interval: float = setting(1.0, unit="s", min=0)  # minimum wall time between two warnings of one kind
    # Lock-step: the robot waits for each command by design; a controller silent this long of wall time hangs.
    # 35 ms (and hold_after): a hung controller is seen held within 50 ms of wall time, with 15 ms for a loaded
    # machine to wake the robot's loop and deliver the frame (with 40 ms: 40.6-50.3 ms seen, 20 runs, load 5-6).
    lockstep_hold_after: float = setting(0.035, unit="s", min=0, strict_min=True)
    lockstep_servo_off_after: float | None = setting(None, unit="s", min="lockstep_hold_after", strict_min=True)
    # A hold caught moving brakes: q_des = q_hold - hold_damping * dq (the encoders' backward difference within
    # +-max_velocity), the term faded out over hold_brake_time: damping the servo lacks. The firmware measures dq
    # itself, without the controller's command latency, so it brakes harder than the controller's hold (whose
    # 0.02 s rings once commands come 2-5 ticks late): the simulated HRP-2's hip caught at 1.8 rad/s by a
    # zero-latency hold moves 9.4 / 5.6 / 4.1 / 3.5 mrad with 0 / 0.01 / 0.02 / 0.04 s, none ringing. 0: no braking.
    hold_damping: float = setting(0.02, unit="s", min=0)
    hold_brake_time: float = setting(0.2, unit="s", min=0)

    def __post_init__(self):
        check_settings(self, HalError)
        joints = tuple(self.joints.items()) if isinstance(self.joints, dict) else tuple(self.joints)
        for item in joints:
            if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str)
                    and isinstance(item[1], JointRateLimits)):
                raise HalError(f"SafetyConfig.joints has {item!r}: expected (joint name, JointRateLimits) pairs")
        object.__setattr__(self, "joints", joints)

    @classmethod
    def from_section(cls, section: Section) -> SafetyConfig:
        """Read a ``[*.safety]`` table (every field optional) and its ``joints.<joint>`` sub-tables."""
        js = section.section("joints", {})
        joints = tuple((name, load_dataclass(JointRateLimits, js.section(name))) for name in js.data)
        return load_dataclass(cls, section, ignore=("joints",), joints=joints)

    def for_lockstep(self) -> SafetyConfig:
        """The same settings with the lock-step watchdog times in force."""
        return replace(self, hold_after=self.lockstep_hold_after, servo_off_after=self.lockstep_servo_off_after)

    def rate_limits(self, info: RobotInfo) -> tuple[np.ndarray, np.ndarray]:
        """``(max_velocity [rad/s], max_acceleration [rad/s^2])`` per joint of ``info`` (overrides applied)."""
        v = np.full(info.nq, self.max_velocity)
        a = np.full(info.nq, self.max_acceleration)
        for name, lim in self.joints:
            if name not in info.joint_names:
                raise HalError(f'safety.joints.{name}: "{name}" is not a joint of {info.name}: expected one of '
                               f"{list(info.joint_names)}")
            i = info.joint_index(name)
            v[i] = lim.max_velocity if lim.max_velocity is not None else v[i]
            a[i] = lim.max_acceleration if lim.max_acceleration is not None else a[i]
        return v, a


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
