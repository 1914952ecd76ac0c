"""Joint trajectories: minimum-jerk segments through waypoints, joints addressed by name; jerk-limited,
time-optimal moves and stops (the `ruckig` library, offline: a whole segment at once).

``right_leg_swing`` is the stairs-climbing-like swing of the paper's motion experiment (section
5.3): from half-sitting, the right foot is lifted high and forward, placed on an imaginary step,
and brought back, close to the actuators' speed limits when ``duration`` is short.

A :class:`JerkLimitedSegment` moves a set of joints from rest to rest, each within its velocity, acceleration and
jerk bounds, all joints arriving together, in the shortest time the bounds allow or in a given minimum duration;
:func:`stopping_segment` brings a moving reference to rest within the acceleration and jerk bounds (the loop's
smooth stop). Why ruckig: it computes the time-optimal profile with jerk limits exactly and fast (tens of
microseconds per segment) and samples it at any time; the seven-phase profile with synchronisation by hand
would repeat a solved problem.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from ruckig import ControlInterface, InputParameter, Result, Ruckig, Trajectory

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


class ForceCompatiblePosture:
    """Joint reference compatible with a force task (paper 5.4: "the reference joint angles were set to be
    compatible with the force task").

    On a contact that is not perfectly rigid, exerting a force moves the joints a little (here the body rises on
    the position-servoed other leg and the contacts deflect). A fixed posture reference ``q0`` then fights the
    force task: in steady state ``(1 + K_f) J^T (f_hat - f_d) = -K_s e_q`` (eq. 12 with ``tau = tau_d``), so the
    position feedback cancels part of the commanded force. The compatible reference is the posture the robot
    takes when the force IS the reference. With the contact compliance ``C`` [m/N] (task-space displacement of
    the contact point per force change: a property of the environment, here the other leg and the contacts)::

        x     = J (q_hat - q0)                    [m]   task-space displacement of the contact point
        q_ref = q0 + J^+ clip(C (f_d - f0), x_max)      (J^+ = J^T (J J^T)^-1, on the task joints)

    ``C`` is calibrated on the first ``calibration`` seconds: least squares of ``x`` on ``f_hat - f0`` (the axes
    whose reference varies) with an intercept and a linear trend (a slow drift is not compliance). Meanwhile, once
    the force reference varies, the reference follows the measured motion (``q0 + J^+ clip(x, x_max)``), so the
    position feedback does not hold the contact back while ``C`` is learned. With ``refit``, ``C`` is refitted
    every ``calibration`` seconds on the samples since the last fit. Both matter because the compliance grows with
    the amplitude (the support leg's joints stick in their friction at small motions). On the simulated robot
    (right foot on the block, 40 N sine) the knee moves 157 urad per N at an 18 N swing and 224 at 31 N, so a ``C``
    calibrated against a fixed reference keeps the force at the smaller swing (docs/control.md).
    The measured motion lags the force, so at a fit the reference would step from the old
    displacement to the new ``C (f_d - f0)``; the step fades out linearly over ``fade`` seconds (bumpless: a
    step of a few mrad at K6 = 0.1 puts a 50 % spike on the contact force).

    After calibration the reference depends on the force reference, not on the measured motion, so the position
    feedback keeps its stiffness (a force task alone has none along its axes; following the measured motion
    instead drifts and, with little stiffness left, oscillates), holds every other direction, and ``x_max``
    bounds how far the task moves it. Its velocity and acceleration are ``J^+ C`` times the force reference's
    first and second backward differences (0 on a clipped axis): the velocity feedback then damps only deviations
    from that motion, and the motor model's direction terms (Coulomb, with ``velocity_feedforward =
    "reference_signs"``) see it.

    The first ``k`` rows of the task Jacobian (``k`` = the length of the forces given) are the axes of the forces.
    """

    def __init__(self, q0: np.ndarray, joints: np.ndarray, calibration: float, max_displacement: float = 0.01,
                 refit: bool = True, fade: float = 0.1):
        """
        Args:
            q0: (n,) [rad] posture reference at the start force ``f0`` (e.g. the start posture).
            joints: Indices of the joints that move the contact (the task Jacobian's columns used).
            calibration: [s] > 0 of data (from the first update on) to estimate ``C``; the force must vary then.
                A period of the force reference is a good choice.
            max_displacement: [m] > 0: largest task-space displacement of the reference, per axis.
            refit: Refit ``C`` every ``calibration`` seconds on the samples since the last fit (kept as it is
                when the force reference did not vary since).
            fade: [s] >= 0: the reference's step at a fit fades out over this time (0: no fade).
        """
        for name, v in (("calibration", calibration), ("max_displacement", max_displacement)):
            if not v > 0:
                raise ControlError(f"{name} = {v!r}: expected > 0")
        if not fade >= 0:
            raise ControlError(f"fade = {fade!r}: expected >= 0 [s]")
        self.q0 = np.array(q0, dtype=float)
        self.joints = np.asarray(joints, dtype=int)
        self.calibration = float(calibration)
        self.max_displacement = float(max_displacement)
        self.refit = bool(refit)
        self.fade = float(fade)
        n = self.q0.size
        self.point = TrajectoryPoint(self.q0.copy(), np.zeros(n), np.zeros(n))
        self.f0: np.ndarray | None = None  # [N] measured force at the first update
        self.t0: float | None = None  # [s] time of the first update
        self.compliance: np.ndarray | None = None  # [m/N] (m, k) C of the last fit (m task rows, k forces)
        self.fits = 0  # number of fits of C so far
        self.displacement = np.zeros(0)  # [m] task-space displacement of the reference, of the last update
        self._step = np.zeros(0)  # [m] the reference's step at the last fit (old minus new), fading out
        self._samples: list[tuple[float, np.ndarray, np.ndarray]] = []  # time [s], x [m], f_hat - f0 [N]
        self._fit_time = 0.0  # [s] from t0, time of the last fit
        self._f_d_range: tuple[np.ndarray, np.ndarray] | None = None  # [N] min, max of f_d since the last fit
        self._last: tuple[float, np.ndarray, np.ndarray | None] | None = None  # time [s], f_d [N], df_d [N/s]

    def update(self, time: float, q_hat: np.ndarray, task_jacobian: np.ndarray | None, f_hat: np.ndarray,
               f_d: np.ndarray) -> TrajectoryPoint:
        """The reference at ``time`` [s] for the estimated angles ``q_hat`` (n,), the task Jacobian (m, n) of the
        last control tick (None: ``q0``), the measured and desired task forces (k,) [N], k <= m. The returned point
        is the same object every call, refreshed in place."""
        q, dq, ddq = self.point.q, self.point.dq, self.point.ddq
        np.copyto(q, self.q0)
        dq.fill(0.0)
        ddq.fill(0.0)
        if task_jacobian is None:
            return self.point
        j = task_jacobian[:, self.joints]
        pinv_t = j.T @ np.linalg.inv(j @ j.T)
        f_hat = np.array(f_hat, dtype=float)
        f_d = np.array(f_d, dtype=float)
        if self.f0 is None:
            self.f0, self.t0 = f_hat.copy(), float(time)
        elapsed = float(time) - self.t0
        x = j @ (np.asarray(q_hat)[self.joints] - self.q0[self.joints])
        if self.compliance is None or self.refit:
            self._samples.append((elapsed, x, f_hat - self.f0))
            lo, hi = self._f_d_range or (f_d, f_d)
            self._f_d_range = (np.minimum(lo, f_d), np.maximum(hi, f_d))
            if elapsed - self._fit_time >= self.calibration:
                old = self.displacement if self.displacement.size else np.zeros_like(x)
                self.compliance, self._fit_time = self._fit(), elapsed
                self.fits += 1
                self._step = old - self.compliance @ (f_d - self.f0)
        if self.compliance is None:  # calibrating: follow the measured motion once the force reference varies
            varies = bool(self._varied_axes().size)
            self.displacement = np.clip(x, -self.max_displacement, self.max_displacement) * varies
            q[self.joints] += pinv_t @ self.displacement
            return self.point
        fading = max(0.0, 1.0 - (elapsed - self._fit_time) / self.fade) if self.fade > 0 else 0.0
        x_ref = np.clip(self.compliance @ (f_d - self.f0) + fading * self._step,
                        -self.max_displacement, self.max_displacement)
        moving = np.abs(x_ref) < self.max_displacement  # a clipped axis holds still
        q[self.joints] += pinv_t @ x_ref
        self.displacement = x_ref
        # Velocity and acceleration of the reference, from the force reference's differences (deterministic, smooth):
        # without them the velocity feedback brakes, and the direction terms of the motor model ignore, the motion
        # the force task needs.
        df_d = None
        if self._last is not None and time > self._last[0]:
            dt = float(time) - self._last[0]
            df_d = (f_d - self._last[1]) / dt
            dq[self.joints] = pinv_t @ (moving * (self.compliance @ df_d))
            if self._last[2] is not None:
                ddq[self.joints] = pinv_t @ (moving * (self.compliance @ ((df_d - self._last[2]) / dt)))
        self._last = (float(time), f_d, df_d)
        return self.point

    def _varied_axes(self) -> np.ndarray:
        """Indices of the force axes whose reference varied since the last fit by more than 10 % of the largest
        variation."""
        spread = self._f_d_range[1] - self._f_d_range[0]
        return np.flatnonzero(spread > 0.1 * spread.max()) if spread.max() > 0 else np.zeros(0, dtype=int)

    def _fit(self) -> np.ndarray:
        """``C`` from the samples since the last fit; only the axes whose reference varied are regressors (the
        others' measured forces follow them through coupling, and would share their compliance at random)."""
        t = np.array([s[0] for s in self._samples])
        x = np.array([s[1] for s in self._samples])
        df = np.array([s[2] for s in self._samples])
        axes = self._varied_axes()
        self._samples, self._f_d_range = [], None
        if not axes.size and self.compliance is not None:
            return self.compliance  # nothing varied: nothing to learn
        c = np.zeros((x.shape[1], df.shape[1]))
        if axes.size:
            a = np.column_stack([df[:, axes], np.ones_like(t), t])
            coef, *_ = np.linalg.lstsq(a, x, rcond=None)
            c[:, axes] = coef[: axes.size].T
        return c  # (m, k): x = C df


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


# Bounds of a reference's stop (the loop's request_stop, the runner's stop before a new task): from 2 rad/s the
# reference comes to rest within about 0.1 s and 0.06 rad.
STOP_ACCELERATION, STOP_JERK = 40.0, 800.0  # [rad/s^2, rad/s^3]


def stopping_segment(q, dq, ddq, a_max=STOP_ACCELERATION, j_max=STOP_JERK) -> JerkLimitedSegment:
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
