"""Joint references of a phase, built from the phase-start posture: hold, sinusoids, waypoints, a table.

Each is a :class:`JointReference`: ``sample(t)`` gives the desired joint state (every joint, RobotInfo
order) at ``t`` [s] from the phase start, ``duration`` its own length (None: endless), ``end`` the posture it
ends in (the next phase starts there), and ``envelope()`` the range of angles and the largest speed per joint
over the phase, which the feasibility check compares with the robot's limits before anything moves.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from ..trajectory import JerkLimitedSegment, JointTrajectory, TrajectoryPoint
from .spec import ReferenceSpec, Wave
from .table import Table

ENVELOPE_STEP = 2e-3  # [s] sampling of a reference's envelope where no closed form is used


class JointReference:
    """Desired joint state of a phase (module doc). Subclasses set ``q0``, ``duration`` and implement
    :meth:`sample`."""

    q0: np.ndarray  # [rad] (n,) the phase-start posture
    duration: float | None = None  # [s] own length, None: endless

    def sample(self, t: float) -> TrajectoryPoint:
        raise NotImplementedError

    def samples(self, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``q, dq, ddq`` (m, n) at the times ``ts`` (m,) [s] (a reference may do it at once)."""
        pts = [self.sample(float(t)) for t in ts]
        return np.array([p.q for p in pts]), np.array([p.dq for p in pts]), np.array([p.ddq for p in pts])

    @property
    def end(self) -> np.ndarray:
        """[rad] (n,) the posture at the end (endless: the start)."""
        return self.sample(self.duration).q.copy() if self.duration is not None else self.q0.copy()

    def envelope(self, length: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Lowest and highest angle [rad] and largest |velocity| [rad/s] (n,) over ``length`` [s] (sampled)."""
        length = length if length is not None else self.duration or 0.0
        ts = np.append(np.arange(0.0, length, ENVELOPE_STEP), length)
        pts = [self.sample(float(t)) for t in ts]
        q = np.array([p.q for p in pts])
        dq = np.abs(np.array([p.dq for p in pts]))
        return q.min(axis=0), q.max(axis=0), dq.max(axis=0)


class Hold(JointReference):
    """The phase-start posture, at rest."""

    def __init__(self, q0: np.ndarray):
        self.q0 = np.array(q0, dtype=float)
        n = self.q0.size
        self._point = TrajectoryPoint(self.q0.copy(), np.zeros(n), np.zeros(n))

    def sample(self, t: float) -> TrajectoryPoint:
        return self._point

    def envelope(self, length):
        return self.q0.copy(), self.q0.copy(), np.zeros_like(self.q0)


class Sinusoids(JointReference):
    """Per joint ``q0 + r(t) min(a0 + a t, max_amplitude) sin(2 pi f t + phase)`` (:class:`~.spec.Wave`), ``r``
    the fade-in ramp (linear over ``ramp`` [s]); the other joints hold."""

    def __init__(self, q0: np.ndarray, joint_names: Sequence[str], waves: Mapping[str, Wave]):
        self.q0 = np.array(q0, dtype=float)
        self.index = np.array([list(joint_names).index(j) for j in waves])
        w = list(waves.values())
        self.a0 = np.array([x.amplitude for x in w])
        self.a = np.array([x.growth for x in w])
        self.amax = np.array([x.max_amplitude for x in w])
        self.omega = 2 * np.pi * np.array([x.frequency for x in w])
        self.phi = np.array([x.phase for x in w])
        self.ramp = np.array([x.ramp for x in w])

    def _amp(self, t: float):
        amp = np.minimum(self.a0 + self.a * t, self.amax)
        damp = np.where(self.a0 + self.a * t < self.amax, self.a, 0.0)
        r = np.where(self.ramp > 0, np.clip(t / np.where(self.ramp > 0, self.ramp, 1.0), 0.0, 1.0), 1.0)
        dr = np.where((self.ramp > 0) & (t < self.ramp), 1.0 / np.where(self.ramp > 0, self.ramp, 1.0), 0.0)
        return r * amp, dr * amp + r * damp

    def sample(self, t: float) -> TrajectoryPoint:
        q, dq, ddq = self.q0.copy(), np.zeros_like(self.q0), np.zeros_like(self.q0)
        A, dA = self._amp(t)
        s, c = np.sin(self.omega * t + self.phi), np.cos(self.omega * t + self.phi)
        q[self.index] += A * s
        dq[self.index] = dA * s + A * self.omega * c
        ddq[self.index] = 2 * dA * self.omega * c - A * self.omega**2 * s  # d2A/dt2 = 0 almost everywhere
        return TrajectoryPoint(q, dq, ddq)

    def samples(self, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(ts, dtype=float)[:, None]
        m = t.shape[0]
        q, dq, ddq = np.tile(self.q0, (m, 1)), np.zeros((m, self.q0.size)), np.zeros((m, self.q0.size))
        A, dA = self._amp(t)
        s, c = np.sin(self.omega * t + self.phi), np.cos(self.omega * t + self.phi)
        q[:, self.index] += A * s
        dq[:, self.index] = dA * s + A * self.omega * c
        ddq[:, self.index] = 2 * dA * self.omega * c - A * self.omega**2 * s
        return q, dq, ddq

    def envelope(self, length):
        T = math.inf if length is None else length
        peak = np.minimum(self.a0 + self.a * T, self.amax)
        dpeak = np.where(self.a0 + self.a * T <= self.amax, self.a, 0.0) + np.where(
            self.ramp > 0, peak / np.where(self.ramp > 0, self.ramp, 1.0), 0.0)
        lo, hi, v = self.q0.copy(), self.q0.copy(), np.zeros_like(self.q0)
        lo[self.index] -= peak
        hi[self.index] += peak
        v[self.index] = peak * self.omega + dpeak
        return lo, hi, v


class MinJerk(JointReference):
    """Minimum-jerk segments through timed waypoints (:class:`~servotau.control.trajectory.JointTrajectory`)."""

    def __init__(self, q0: np.ndarray, joint_names: Sequence[str], waypoints: Sequence[tuple[float, Mapping]]):
        self.q0 = np.array(q0, dtype=float)
        self.traj = JointTrajectory(joint_names, self.q0, waypoints)
        self.duration = self.traj.duration

    def sample(self, t: float) -> TrajectoryPoint:
        return self.traj.sample(t)

    def envelope(self, length):  # a quintic segment moves monotonically: extremes at the waypoints
        pts = self.traj.points
        peak = 1.875 * np.max(np.abs(np.diff(pts, axis=0)) / np.diff(self.traj.times)[:, None], axis=0)
        return pts.min(axis=0), pts.max(axis=0), peak


class JerkLimited(JointReference):
    """Time-optimal, jerk-limited rest-to-rest moves through waypoints (:mod:`.profile`, ruckig)."""

    def __init__(self, q0: np.ndarray, targets: Sequence[np.ndarray], v_max, a_max, j_max,
                 min_duration: float = 0.0):
        self.q0 = np.array(q0, dtype=float)
        self.segments, start = [], self.q0
        for q in targets:
            self.segments.append(JerkLimitedSegment(start, q, v_max, a_max, j_max))
            start = np.asarray(q, dtype=float)
        self.optimal = sum(s.duration for s in self.segments)  # [s] the time-optimal length
        if min_duration > self.optimal and self.segments:  # stretch the last segment to the phase's duration
            last = self.segments[-1]
            rest = min_duration - (self.optimal - last.duration)
            self.segments[-1] = JerkLimitedSegment(last.q0, last.q1, v_max, a_max, j_max, rest)
        self.starts = np.cumsum([0.0] + [s.duration for s in self.segments])
        self.duration = float(self.starts[-1])

    def sample(self, t: float) -> TrajectoryPoint:
        k = int(np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, len(self.segments) - 1))
        return TrajectoryPoint(*self.segments[k].sample(t - self.starts[k]))


class Tabled(JointReference):
    """A trajectory table (:mod:`.table`): a clamped cubic spline through its rows, absolute angles (or offsets
    from the phase start with ``relative``)."""

    def __init__(self, q0: np.ndarray, joint_names: Sequence[str], table: Table, relative: bool = False):
        from scipy.interpolate import CubicSpline

        self.q0 = np.array(q0, dtype=float)
        self.table = table
        self.index = np.array([list(joint_names).index(j) for j in table.joints])
        values = table.q + (self.q0[self.index] if relative else 0.0)
        self.spline = CubicSpline(table.t, values, bc_type="clamped")
        self.first = values[0]
        self.duration = float(table.t[-1])

    def sample(self, t: float) -> TrajectoryPoint:
        t = min(max(t, 0.0), self.duration)
        q, dq, ddq = self.q0.copy(), np.zeros_like(self.q0), np.zeros_like(self.q0)
        q[self.index] = self.spline(t)
        dq[self.index] = self.spline(t, 1)
        ddq[self.index] = self.spline(t, 2)
        return TrajectoryPoint(q, dq, ddq)


def waypoint_targets(spec: ReferenceSpec, q0: np.ndarray, joint_names: Sequence[str],
                     q_task: np.ndarray | None = None) -> list[np.ndarray]:
    """The posture (n,) [rad] of each waypoint: its targets, deltas from ``q0`` (the phase start), else the
    previous waypoint's; ``start = true``: ``q_task`` (the task's start posture, default ``q0``)."""
    index = {j: i for i, j in enumerate(joint_names)}
    out, q = [], np.array(q0, dtype=float)
    for w in spec.waypoints:
        q = np.array(q_task if q_task is not None else q0, dtype=float) if w.start else q.copy()
        for j, v in w.targets.items():
            q[index[j]] = v
        for j, d in w.delta.items():
            q[index[j]] = q0[index[j]] + d
        out.append(q)
    return out
