"""Data collection for actuator identification, through the HAL (paper section 3.4).

Two phases, run on any backend (simulator or real robot):

- High velocity (3.4.2): per joint, ``q_des(t) = q0 + (a0 + a t) sin(2 pi f t)``. The amplitude is
  bounded so that the joint stays inside its limits (with a margin) and so that the expected
  position error stays below a fraction of the robot's servo-cut threshold.
- High torque at near-zero velocity (3.4.1): the robot holds a set of configurations while
  external forces load the joints. On a real robot a person pushes, prompted by the tool; in the
  simulator the scenario's scripted operator does (config/scenarios/identification.toml).

Each tick's frame and command go to ``record(frame, q_des)``, so the caller decides where they go
(the project's Parquet log in ``servotau identify collect``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from servotau.config import setting
from servotau.errors import IdentificationError
from servotau.hal.types import SensorFrame

K_V_GUESS = 0.015  # [rad/(rad/s)] a conservative (large) friction slope, above HRP-2's identified values


@dataclass(frozen=True)
class SweepPlan:
    """High-velocity excitation of one joint around ``q0`` [rad]."""

    joint: str
    a0: float = setting(0.02, unit="rad", min=0.0)  # initial amplitude
    a: float = setting(0.05, unit="rad/s", min=0.0)  # amplitude growth
    frequency: float = setting(0.6, unit="Hz", min=0.0, strict_min=True)
    duration: float = setting(12.0, unit="s", min=0.0, strict_min=True)
    limit_margin: float = setting(0.1, unit="rad", min=0.0)  # kept from each joint limit
    error_fraction: float = setting(0.5, unit="-", min=0.0, strict_min=True)
    """Expected ``|q_des - q|`` kept below this fraction of the servo-cut threshold."""


@dataclass(frozen=True)
class HoldPlan:
    """High-torque phase: hold each configuration (joint name -> angle [rad]) for ``hold`` seconds."""

    configurations: Sequence[Mapping[str, float]] = field(default_factory=list)
    move: float = setting(2.0, unit="s", min=0.0, strict_min=True)  # to reach each configuration
    hold: float = setting(6.0, unit="s", min=0.0, strict_min=True)  # held while external forces load the joints


def sweep_amplitude_bound(plan: SweepPlan, q0: float, q_min: float, q_max: float, max_error: float) -> float:
    """Largest amplitude [rad] allowed by the joint limits and by the position-error bound."""
    room = min(q0 - q_min, q_max - q0) - plan.limit_margin
    if room <= 0:
        raise IdentificationError(
            f"{plan.joint}: q0 = {q0:.3f} rad is within {plan.limit_margin} rad of a limit "
            f"[{q_min:.3f}, {q_max:.3f}]: expected a start posture with room to move"
        )
    by_error = plan.error_fraction * max_error / (K_V_GUESS * 2 * math.pi * plan.frequency)
    return min(room, by_error)


def sweep(plan: SweepPlan, q0: float, bound: float, t: float) -> float:
    """Desired angle [rad] of the swept joint at time ``t`` [s] from the start of the sweep."""
    amp = min(plan.a0 + plan.a * t, bound)
    ramp = min(1.0, t / 0.5)  # half a second to fade in from rest
    return q0 + ramp * amp * math.sin(2 * math.pi * plan.frequency * t)


def _min_jerk(s: float) -> float:
    s = min(max(s, 0.0), 1.0)
    return 10 * s**3 - 15 * s**4 + 6 * s**5


class Collector:
    """Runs collection phases on a HAL backend, one ``read``/``write`` per tick."""

    def __init__(
        self,
        backend,
        record: Callable[[SensorFrame, np.ndarray], None],
        progress: Callable[[str], None] = print,
    ):
        self.backend = backend
        self.info = backend.info
        self.record = record
        self.progress = progress
        self.frame = backend.read()
        self.q_des = self.frame.q.copy()

    def _tick(self, q_des: np.ndarray) -> None:
        self.backend.write(dict(zip(self.info.joint_names, q_des, strict=True)))
        self.record(self.frame, q_des.copy())
        self.q_des = q_des
        self.frame = self.backend.read()

    def _ticks(self, seconds: float) -> range:
        return range(int(round(seconds / self.info.period)))

    def move_to(self, targets: Mapping[str, float], seconds: float) -> None:
        """Minimum-jerk move of the named joints to ``targets`` [rad] in ``seconds``."""
        start = self.q_des.copy()
        goal = start.copy()
        for name, value in targets.items():
            goal[self.info.joint_index(name)] = value
        n = max(1, len(self._ticks(seconds)))
        for k in range(n):
            self._tick(start + _min_jerk((k + 1) / n) * (goal - start))

    def run_sweep(self, plan: SweepPlan) -> None:
        j = self.info.joint_index(plan.joint)
        q0 = float(self.q_des[j])
        bound = sweep_amplitude_bound(plan, q0, self.info.q_min[j], self.info.q_max[j], self.info.max_position_error)
        self.progress(f"sweep {plan.joint}: {plan.duration:.0f} s at {plan.frequency} Hz, amplitude <= {bound:.3f} rad")
        q = self.q_des.copy()
        for k in self._ticks(plan.duration):
            t = k * self.info.period
            q[j] = sweep(plan, q0, bound, t)
            self._tick(q)
            if k % int(2.0 / self.info.period) == 0 and k:
                self.progress(f"  {plan.joint}: {t:.0f}/{plan.duration:.0f} s")
        self.move_to({plan.joint: q0}, 1.0)

    def run_holds(self, plan: HoldPlan) -> None:
        for i, config in enumerate(plan.configurations):
            self.progress(f"hold {i + 1}/{len(plan.configurations)}: moving to {dict(config)}")
            self.move_to(config, plan.move)
            self.progress(f"  PUSH NOW on the end-effectors for {plan.hold:.0f} s (large torques, little motion)")
            hold = self.q_des.copy()
            for _ in self._ticks(plan.hold):
                self._tick(hold)
