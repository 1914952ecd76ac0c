"""Velocity and acceleration limits of the desired angles the robot side applies (per joint, per tick).

:class:`RateLimiter` keeps the last applied ``q_des`` and its velocity and bounds the next one so that,
tick to tick in robot time (one period per tick),

- ``|q_des[k] - q_des[k-1]| / period <= max_velocity`` [rad/s] and
- ``|v[k] - v[k-1]| / period <= max_acceleration`` [rad/s^2],

braking early enough to reach a far target without overshooting it (the largest velocity from which a
constant deceleration ``max_acceleration`` still stops within the remaining distance); a target that moved
since the last command by a step within both limits is applied unchanged (a moving reference); a step toward
the measured angles is free (it lowers the servo's effort; beyond them the limits apply). The firmware
applies the bounded value ("clamp") or holds when it differs from the command ("trip").
"""

from __future__ import annotations

import numpy as np

_TOL = 1e-9  # [rad] a bounded value this close to the target is the target (float rounding)


class RateLimiter:
    """Bounds the velocity and acceleration of successive desired angles (arrays in RobotInfo order)."""

    def __init__(self, max_velocity: np.ndarray, max_acceleration: np.ndarray, period: float):
        self.v_max = np.asarray(max_velocity, dtype=float)  # [rad/s]
        self.a_max = np.asarray(max_acceleration, dtype=float)  # [rad/s^2]
        self.dt = float(period)  # [s]
        self._q: np.ndarray | None = None  # last applied q_des [rad]
        self._v = np.zeros_like(self.v_max)  # its velocity [rad/s]
        self._target: np.ndarray | None = None  # the last target bounded [rad]
        self._start: np.ndarray | None = None  # where the last bound started (after a free step toward q) [rad]

    @property
    def q(self) -> np.ndarray | None:
        """The last applied q_des [rad] (None before the first)."""
        return self._q

    def reset(self, q: np.ndarray) -> None:
        """Start again from ``q`` [rad] at rest (a hold, or before the first command)."""
        self._q = np.array(q, dtype=float)
        self._v = np.zeros_like(self.v_max)
        self._target = self._start = None

    def bound(self, target: np.ndarray, q: np.ndarray | None = None) -> np.ndarray:
        """The desired angles closest to ``target`` [rad] within the limits (not yet applied; call
        :meth:`reset` first). ``q``: the measured angles [rad] (NaN where invalid): a step of q_des toward them
        is free (it lowers the servo's effort and cannot drive the joint: a hold catching a moving joint brakes
        at once); beyond them the limits apply, from there at rest."""
        dt, a = self.dt, self.a_max
        start, v0 = self._q, self._v
        if q is not None:
            ok = np.isfinite(q)
            toward = np.where(ok, np.clip(target, np.minimum(start, q), np.maximum(start, q)), start)
            jumped = toward != start
            if jumped.any():
                start, v0 = toward, np.where(jumped, 0.0, v0)
        self._start = start
        e = target - start
        # Braking from v (this tick's step) by a * dt per tick covers dt * ((m + 1) v - a dt m (m + 1) / 2),
        # m = floor(v / (a dt)); the largest v that stops within |e|: m from the continuous bound
        # m (m + 1) / 2 <= |e| / (a dt^2), then v solved for that m.
        dist = np.abs(e)
        m = np.floor(np.sqrt(0.25 + 2.0 * dist / (a * dt * dt)) - 0.5)
        v_brake = (dist / dt + a * dt * m * (m + 1) / 2) / (m + 1)
        speed = np.minimum(np.minimum(dist / dt, v_brake), self.v_max)
        v = np.clip(np.sign(e) * speed, v0 - a * dt, v0 + a * dt)
        v = np.clip(v, -self.v_max, self.v_max)
        out = start + v * dt
        # a target that moved since the last command, by a step within both limits, is applied as commanded: a
        # moving reference's next point is on its way, not a point to stop at (the braking bound would cap a 1 ms
        # step at about sqrt(2 a |e|), 2.4 rad/s for 1.5 mrad); a target that stays is approached braking
        v_step = e / dt
        moving = target != self._target if self._target is not None else np.ones(target.shape, dtype=bool)
        within = moving & (np.abs(v_step) <= self.v_max) & (np.abs(v_step - v0) <= a * dt)
        self._target = np.array(target, dtype=float)
        near = within | (np.abs(out - target) <= _TOL)
        out[near] = target[near]
        return out

    def applied(self, q_des: np.ndarray) -> None:
        """``q_des`` [rad] was applied this tick (as bounded: its velocity counts from the free step's end)."""
        start = self._start if self._start is not None else self._q
        self._v = (q_des - start) / self.dt
        self._q = np.array(q_des, dtype=float)
        self._start = None
