"""Jerk-limited, time-optimal joint motions (the `ruckig` library, offline: a whole segment at once).

A :class:`JerkLimitedSegment` moves a set of joints from rest to rest, each within its velocity,
acceleration and jerk bounds, all joints arriving together (time-synchronised), in the shortest time the
bounds allow or in a given minimum duration. :func:`stopping_segment` brings a moving reference to rest
within the acceleration and jerk bounds (the loop's smooth stop).

Why ruckig: it computes the time-optimal profile with jerk limits exactly and fast (tens of microseconds per
segment), and samples it at any time; writing the seven-phase profile with synchronisation by hand would
repeat a solved problem.
"""

from __future__ import annotations

import numpy as np
from ruckig import ControlInterface, InputParameter, Result, Ruckig, Trajectory

from servotau.errors import ControlError


class JerkLimitedSegment:
    """Rest-to-rest motion of ``q0`` -> ``q1`` (n,) [rad] within ``v_max`` [rad/s], ``a_max`` [rad/s^2] and
    ``j_max`` [rad/s^3] (scalars or (n,)); at least ``min_duration`` [s] long."""

    def __init__(self, q0, q1, v_max, a_max, j_max, min_duration: float = 0.0):
        self.q0 = np.array(q0, dtype=float)
        self.q1 = np.array(q1, dtype=float)
        n = self.q0.size
        self.moving = np.flatnonzero(np.abs(self.q1 - self.q0) > 1e-12)
        self._traj = None
        self.duration = float(min_duration)
        if not self.moving.size:
            return
        m = self.moving.size
        inp = InputParameter(m)
        inp.current_position = self.q0[self.moving].tolist()
        inp.target_position = self.q1[self.moving].tolist()
        inp.current_velocity = inp.current_acceleration = [0.0] * m
        inp.target_velocity = inp.target_acceleration = [0.0] * m
        inp.max_velocity = np.broadcast_to(np.asarray(v_max, float), (n,))[self.moving].tolist()
        inp.max_acceleration = np.broadcast_to(np.asarray(a_max, float), (n,))[self.moving].tolist()
        inp.max_jerk = np.broadcast_to(np.asarray(j_max, float), (n,))[self.moving].tolist()
        if min_duration > 0:
            inp.minimum_duration = float(min_duration)
        self._traj = Trajectory(m)
        result = Ruckig(m).calculate(inp, self._traj)
        if result not in (Result.Working, Result.Finished):
            raise ControlError(f"jerk-limited profile: no solution ({result})")
        self.duration = float(self._traj.duration)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q [rad], dq [rad/s], ddq [rad/s^2] (n,) at ``t`` [s] from the start (held at the ends)."""
        q, dq, ddq = self.q0.copy(), np.zeros_like(self.q0), np.zeros_like(self.q0)
        if self._traj is None:
            return q, dq, ddq
        p, v, a = self._traj.at_time(min(max(t, 0.0), self.duration))
        q[self.moving], dq[self.moving], ddq[self.moving] = p, v, a
        return q, dq, ddq


def stopping_segment(q, dq, ddq, a_max, j_max) -> JerkLimitedSegment:
    """The fastest motion from the state ``q, dq, ddq`` (n,) to rest within ``a_max`` [rad/s^2] and ``j_max``
    [rad/s^3] (velocity control: the position ends where braking leaves it)."""
    seg = JerkLimitedSegment.__new__(JerkLimitedSegment)
    seg.q0 = np.array(q, dtype=float)
    n = seg.q0.size
    seg.moving = np.flatnonzero((np.abs(np.asarray(dq)) > 1e-9) | (np.abs(np.asarray(ddq)) > 1e-9))
    seg.q1, seg._traj, seg.duration = seg.q0.copy(), None, 0.0
    if not seg.moving.size:
        return seg
    m = seg.moving.size
    inp = InputParameter(m)
    inp.control_interface = ControlInterface.Velocity
    inp.current_position = seg.q0[seg.moving].tolist()
    inp.current_velocity = np.asarray(dq, float)[seg.moving].tolist()
    inp.current_acceleration = np.asarray(ddq, float)[seg.moving].tolist()
    inp.target_velocity = inp.target_acceleration = [0.0] * m
    inp.max_acceleration = np.broadcast_to(np.asarray(a_max, float), (n,))[seg.moving].tolist()
    inp.max_jerk = np.broadcast_to(np.asarray(j_max, float), (n,))[seg.moving].tolist()
    seg._traj = Trajectory(m)
    result = Ruckig(m).calculate(inp, seg._traj)
    if result not in (Result.Working, Result.Finished):
        raise ControlError(f"stopping profile: no solution ({result})")
    seg.duration = float(seg._traj.duration)
    seg.q1 = seg.sample(seg.duration)[0]
    return seg
