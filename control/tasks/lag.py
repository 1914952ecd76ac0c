"""What following a reference takes, predicted before anything moves: the command error, and what the safety will
read (the estimated speed and torque).

A position servo follows its reference with a lag: to produce the torque ``tau`` of the motion at velocity ``dq`` it
needs the command error (the paper's eq. 10, the identified motor model of control.toml's ``motors``)::

    tau    = M(q_d) ddq_d + h(q_d, dq_d)                 (the robot's free dynamics along the reference, RNEA)
    dq_err = k_tau tau + k_v dq_d + k_c sign(dq_d)       [rad] = q_des - q, what the safety's command_error checks

in position mode (``q_des = q_d``: the tracking error is that lag) as in torque mode (the law's feedforward is that
model). The same model is the position servo's dynamics about the reference: the joint's error ``x = q - q_d`` obeys
``k_tau M_jj x'' + k_v x' + x = -dq_err`` (``M_jj`` the joint's inertia, its mean over the phase), a second-order
response that overshoots when the servo has little damping. The safety's ``joint_velocity`` and ``joint_torque``
checks read the estimator's outputs, not the motion: its encoder filter (last-sample Savitzky-Golay, the loop's
variant) amplifies a joint's speed above a few Hz (window 80, order 3: x 1.15 at 5 Hz, x 1.41 at 7 Hz). So the
predicted speed ``dq_hat`` is that filter applied to the servo's response and to the reference itself (the larger:
the torque law tracks the reference), and the predicted torque the reference's plus ``M_jj`` times the filtered
acceleration's excess over the reference's (the larger of the two).

:func:`~.build.check_feasible` refuses a phase whose predicted ``|dq_hat|`` exceeds ``(1 - VELOCITY_MARGIN[mode])
max_velocity`` (the phase's mode: an operator's switch to torque in a position phase keeps the position margin);
:func:`check_lag` one whose ``|tau|`` exceeds ``(1 - TORQUE_MARGIN) max_torque`` or ``|dq_err|`` exceeds ``(1 -
COMMAND_MARGIN) max_command_error``; the messages name the phase, the joint, the value and the limit. Joints without
a motor model (position-controlled) follow their reference exactly in this prediction. It is free motion (no contact
wrench): a force phase is not checked here.

The references are sampled every :data:`STEP` and interpolated (cubic Hermite, from ``q`` and ``dq``) to the control
period for the filters: quick enough for a long task (the identification task's 102 s), exact below ~20 Hz.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from servotau.actuator import MotorModel
from servotau.hal.types import RobotInfo
from servotau.signal.savgol import savgol_coeffs

from ..config import SafetyLimits
from ..dynamics import RobotDynamics
from .references import Hold

STEP = 0.01  # [s] sampling of a reference for the dynamics (the filters run at the control period)
VELOCITY_MARGIN = {"position": 0.06, "torque": 0.12}  # [-] share of max_velocity kept, per mode, for what the
# prediction leaves out: in position mode noise and the model's error (measured within -1.6..+1.5 % of the
# prediction), in torque mode the law's own overshoot of its reference (measured up to 12.5 %). It does not cover a
# torque loop that resonates with its reference (hip yaw and roll excited at 4 Hz: CHANGELOG).
TORQUE_MARGIN = 0.1  # [-] share of max_torque kept for the estimator's torque beyond the prediction
COMMAND_MARGIN = 0.25  # [-] share of max_command_error kept for what the model does not predict (the feedback,
# the estimator's noise, the model's own error: the measured command error was 1.05-1.21 x the predicted)


@dataclass(frozen=True)
class LagPrediction:
    """Per joint (n,), the largest over a phase: the command error ``|q_des - q|`` [rad] (0 without a motor model)
    and when [s from the phase start], the estimated speed [rad/s] and torque [N m]."""

    command_error: np.ndarray
    t_command_error: np.ndarray
    velocity: np.ndarray
    torque: np.ndarray


class LagModel:
    """The robot's dynamics, the motor models of the joints that have one and the estimator's encoder filter (module
    doc). Not thread-safe (one dynamics buffer): one per thread that checks tasks.

    Args:
        info: The robot.
        motors: Motor models by joint name (the servo-error models with ``k_tau`` are used).
        base: ``fixed`` or ``floating`` (control.toml ``base``; the prediction is with the base at rest).
        encoders: (window [samples], order) of the estimator's last-sample encoder filter.
    """

    def __init__(self, info: RobotInfo, motors: Mapping[str, MotorModel], base: str = "fixed",
                 encoders: tuple[int, int] = (80, 3)):
        self.info = info
        self.dynamics = RobotDynamics(info.model_path, info.joint_names, base, info.root_joint)
        self.period = float(info.period)
        window, order = int(encoders[0]), int(encoders[1])
        self.d1 = savgol_coeffs(window, order, deriv=1, delta=self.period, pos=window - 1, use="conv")
        self.d2 = savgol_coeffs(window, order, deriv=2, delta=self.period, pos=window - 1, use="conv")
        self.window = window
        self.index = np.array(sorted(info.joint_names.index(j) for j, m in motors.items()
                                     if j in info.joint_names and m.k_tau is not None), dtype=int)
        by_index = {info.joint_names.index(j): m for j, m in motors.items() if j in info.joint_names}
        self.k_tau = np.array([by_index[i].k_tau for i in self.index])
        self.k_v = np.array([by_index[i].k_v for i in self.index])
        self.k_c = np.array([by_index[i].k_c or 0.0 for i in self.index])

    def predict(self, reference, length: float | None) -> LagPrediction:
        """:class:`LagPrediction` of ``reference`` (a :class:`~.references.JointReference`) over ``length`` [s]
        (None: its own duration)."""
        n, dyn = self.info.nq, self.dynamics
        length = length if length is not None else reference.duration or 0.0
        if isinstance(reference, Hold) or length <= 0.0:
            length = 0.0
        ts = np.append(np.arange(0.0, length, STEP), length) if length > 0 else np.array([0.0])
        q, dq, ddq = reference.samples(ts)
        tau, m_jj, buf = np.zeros_like(q), np.zeros(n), np.zeros(n)
        for k in range(len(ts)):
            dyn.set_state(q[k], dq[k])
            dyn.inverse_dynamics(ddq[k], buf)
            tau[k] = buf
            if k % 20 == 0:
                m_jj += np.diag(dyn.mass_matrix())
        m_jj /= (len(ts) - 1) // 20 + 1
        idx = self.index
        err = np.zeros((len(ts), n))
        err[:, idx] = self.k_tau * tau[:, idx] + self.k_v * dq[:, idx] + self.k_c * np.sign(dq[:, idx])
        worst = np.abs(err).argmax(axis=0)
        velocity, torque = np.abs(dq).max(axis=0), np.abs(tau).max(axis=0)
        if length > 0:
            v_hat, tau_hat = self._estimated(ts, q, dq, ddq, tau, err, m_jj)
            np.maximum(velocity, v_hat, out=velocity)
            np.maximum(torque, tau_hat, out=torque)
        return LagPrediction(np.abs(err).max(axis=0), ts[worst], velocity, torque)

    def _estimated(self, ts, q, dq, ddq, tau, err, m_jj) -> tuple[np.ndarray, np.ndarray]:
        """The largest estimated speed and torque (n,): the encoder filter on the servo's response and on the
        reference, at the control period (module doc); the torque ``tau + M_jj (ddq_hat - ddq_d)`` per joint."""
        from scipy.interpolate import CubicHermiteSpline  # here: scipy.interpolate and scipy.signal take about
        from scipy.signal import lfilter  # a second to import, and only a task's start needs them

        dt, idx, w = self.period, self.index, self.window
        fine = np.arange(0.0, ts[-1], dt)
        q_ref = CubicHermiteSpline(ts, q, dq, axis=0)(fine)
        q_servo = q_ref.copy()
        if idx.size:
            e = np.column_stack([np.interp(fine, ts, err[:, i]) for i in idx])
            g = 2.0 / dt
            for c, i in enumerate(idx):  # x / e = -1 / (A s^2 + B s + 1), bilinear s = g (z - 1) / (z + 1)
                A, B = self.k_tau[c] * m_jj[i], self.k_v[c]
                den = [A * g * g + B * g + 1.0, 2.0 - 2.0 * A * g * g, A * g * g - B * g + 1.0]
                q_servo[:, i] += lfilter([-1.0, -2.0, -1.0], den, e[:, c])
        tau_ref = np.column_stack([np.interp(fine, ts, col) for col in tau.T])
        ddq_ref = np.column_stack([np.interp(fine, ts, col) for col in ddq.T])
        v_hat, tau_hat = np.zeros(self.info.nq), np.zeros(self.info.nq)
        for qq in (q_servo, q_ref):
            moving = np.flatnonzero(np.ptp(qq, axis=0) > 0.0)  # the filters of joints at rest read 0
            padded = np.vstack([np.repeat(qq[:1, moving], w, axis=0), qq[:, moving]])  # at rest before the phase
            vel = np.abs(lfilter(self.d1, [1.0], padded, axis=0)[w:])
            acc = lfilter(self.d2, [1.0], padded, axis=0)[w:]
            v_hat[moving] = np.maximum(v_hat[moving], vel.max(axis=0, initial=0.0))
            est = np.abs(tau_ref[:, moving] + m_jj[moving] * (acc - ddq_ref[:, moving])).max(axis=0, initial=0.0)
            tau_hat[moving] = np.maximum(tau_hat[moving], est)
        return v_hat, tau_hat


def check_lag(where: str, prediction: LagPrediction, info: RobotInfo, limits: SafetyLimits) -> str | None:
    """Why a phase is refused (the torque or the command error it needs beyond the safety's limits, module doc; the
    speed is :func:`~.build.check_feasible`'s), or None; the message names ``where`` (the task's file and phase), the
    joint, the predicted value and the limit."""
    names = info.joint_names
    tau_lim = (1.0 - TORQUE_MARGIN) * limits.max_torque
    over = np.flatnonzero(prediction.torque > tau_lim)
    if over.size:
        i = int(over[np.argmax(prediction.torque[over] / tau_lim[over])])
        return (f"{where}: joint {names[i]} needs {prediction.torque[i]:.1f} N m (the robot's dynamics along the "
                f"reference, as the estimator will read it), above {tau_lim[i]:.1f} N m = (1 - {TORQUE_MARGIN:g}) x "
                f"the safety's max_torque {limits.max_torque[i]:g} N m (control.toml [safety]): expected a slower "
                "motion")
    cmd_lim = (1.0 - COMMAND_MARGIN) * limits.max_command_error
    over = np.flatnonzero(prediction.command_error > cmd_lim)
    if not over.size:
        return None
    i = int(over[np.argmax(prediction.command_error[over] / cmd_lim[over])])
    return (f"{where}: joint {names[i]} needs a command error |q_des - q| of {prediction.command_error[i]:.3f} rad at "
            f"t = {prediction.t_command_error[i]:.2f} s (motor model k_tau tau + k_v dq along the reference), above "
            f"{cmd_lim[i]:.3f} rad = (1 - {COMMAND_MARGIN:g}) x the safety's max_command_error "
            f"{limits.max_command_error[i]:g} rad (control.toml [safety]): expected a slower motion")


