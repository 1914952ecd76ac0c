"""Joint trajectories: minimum-jerk segments through waypoints, joints addressed by name.

``right_leg_swing`` is the stairs-climbing-like swing of the paper's motion experiment (section
5.3): from half-sitting, the right foot is lifted high and forward, placed on an imaginary step,
and brought back, close to the actuators' speed limits when ``duration`` is short.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from servotau.errors import ControlError


@dataclass(frozen=True)
class TrajectoryPoint:
    """Desired position [rad], velocity [rad/s] and acceleration [rad/s^2], RobotInfo joint order."""

    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray


class JointTrajectory:
    """Minimum-jerk (quintic, zero end velocity and acceleration) segments between waypoints."""

    def __init__(self, joint_names: Sequence[str], q_start: np.ndarray, waypoints: Sequence[tuple[float, Mapping]]):
        """``waypoints``: (time [s], {joint name: angle [rad]}) in increasing time; joints not named in a
        waypoint keep their previous value. Time 0 is ``q_start``."""
        self.joint_names = tuple(joint_names)
        index = {j: i for i, j in enumerate(self.joint_names)}
        times, points = [0.0], [np.asarray(q_start, dtype=float).copy()]
        for t, targets in waypoints:
            if not t > times[-1]:
                raise ControlError(f"waypoint time {t} s: expected > {times[-1]} s (increasing times)")
            q = points[-1].copy()
            for name, value in targets.items():
                if name not in index:
                    raise ControlError(f'waypoint joint "{name}": expected one of {list(self.joint_names)}')
                q[index[name]] = value
            times.append(float(t))
            points.append(q)
        self.times = np.array(times)
        self.points = np.array(points)

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def sample(self, t: float) -> TrajectoryPoint:
        """Desired state at time ``t`` [s] (held at the ends)."""
        k = int(np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2))
        t0, t1 = self.times[k], self.times[k + 1]
        T = t1 - t0
        s = float(np.clip((t - t0) / T, 0.0, 1.0))
        p = 10 * s**3 - 15 * s**4 + 6 * s**5
        dp = (30 * s**2 - 60 * s**3 + 30 * s**4) / T if 0 < s < 1 else 0.0
        ddp = (60 * s - 180 * s**2 + 120 * s**3) / T**2 if 0 < s < 1 else 0.0
        delta = self.points[k + 1] - self.points[k]
        return TrajectoryPoint(q=self.points[k] + p * delta, dq=dp * delta, ddq=ddp * delta)


def right_leg_swing(joint_names: Sequence[str], q_start: np.ndarray, duration: float = 4.0) -> JointTrajectory:
    """Stairs-climbing-like swing of the right leg from ``q_start`` (half-sitting) lasting ``duration`` [s]."""
    i = {j: k for k, j in enumerate(joint_names)}
    q0 = {j: float(q_start[i[j]]) for j in ("RLEG_JOINT1", "RLEG_JOINT2", "RLEG_JOINT3", "RLEG_JOINT4", "RLEG_JOINT5")}
    s = duration / 4.0
    lift = {"RLEG_JOINT1": q0["RLEG_JOINT1"] + 0.08, "RLEG_JOINT2": -1.35, "RLEG_JOINT3": 1.9, "RLEG_JOINT4": -0.55,
            "RLEG_JOINT5": q0["RLEG_JOINT5"] - 0.08}
    step = {"RLEG_JOINT1": q0["RLEG_JOINT1"] + 0.04, "RLEG_JOINT2": -1.1, "RLEG_JOINT3": 1.2, "RLEG_JOINT4": -0.1,
            "RLEG_JOINT5": q0["RLEG_JOINT5"] - 0.04}
    return JointTrajectory(joint_names, q_start, [(s, lift), (2 * s, step), (3 * s, lift), (4 * s, q0)])
