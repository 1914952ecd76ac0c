"""Joint-torque controller of the paper (eq. 10-11): desired torques -> position-error command.

::

    tau*   = tau_d + K_p e_tau + K_i integral(e_tau) dt,   e_tau = tau_d - tau_hat      (eq. 11)
    dq_err = K_tau tau* + K_v dq_hat [+ k_c tanh(dq_hat / v_s)] + extra                   (eq. 10)
    extra  = model(tau*, dq_hat, q_hat, ddq_hat, t, q_des) - (K_tau tau* + K_v dq_hat + k_c sign(dq_hat))
    q_des  = q + dq_err                                     (the servo only takes desired angles)

``K_tau``, ``K_v``, ``k_c`` are the identified motor model (:class:`~servotau.actuator.MotorModel`).
The integral is clamped so that ``|K_i integral| <= integral_limit`` (anti-windup).

``extra`` is what the motor model's extra effect terms (model workbench: ``deadzone``, ``direction_gain``,
``stribeck``, ``delay``, ...) add to the paper's linear model, evaluated one tick at a time by an
:class:`~servotau.actuator.online.OnlineModel` per joint (effects with memory keep their
state there; it advances once per :meth:`JointTorqueController.update`). Every term of the file is used: a
term the workbench does not know raises at construction. With a ``delay`` term the model reads this tick's
command; ``OnlineModel.command`` solves ``q_des = q_hat + model(q_des)`` for it. A joint without ``k_c``
then gets exactly the model's prediction; with ``k_c`` the Coulomb sign is the smoothed one above.

Joints without gains (position-controlled) have every gain at 0: their outputs are 0.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence

import numpy as np

from servotau.actuator import MotorModel, OnlineModel, checked_online_model
from servotau.errors import ControlError, IdentificationError

from .config import ControlConfig, JointGains

log = logging.getLogger(__name__)


class JointTorqueController:
    """Eq. 10-11 vectorised over the joints, without allocation per tick."""

    def __init__(self, joint_names: Sequence[str], motors: Mapping[str, MotorModel], gains: Mapping[str, JointGains],
                 period: float, sign_velocity: float = ControlConfig.sign_velocity):
        """
        Args:
            joint_names: All joints, RobotInfo order.
            motors: Motor model of each joint in ``gains``.
            gains: Gains of the torque-controlled joints (``k_p``, ``k_i``, ``integral_limit`` are used here).
            period: Control period [s].
            sign_velocity: [rad/s] smoothing of the Coulomb sign: ``tanh(dq / sign_velocity)``.
        """
        self.joint_names = tuple(joint_names)
        n = len(self.joint_names)
        if not period > 0:
            raise ControlError(f"period = {period!r}: expected > 0 [s]")
        if not sign_velocity > 0:
            raise ControlError(f"sign_velocity = {sign_velocity!r}: expected > 0 [rad/s]")
        self.period = float(period)
        self.sign_velocity = float(sign_velocity)
        self.k_tau, self.k_v, self.k_c = np.zeros(n), np.zeros(n), np.zeros(n)
        self.k_p, self.k_i, self.integral_limit = np.zeros(n), np.zeros(n), np.zeros(n)
        # Joints with extra terms: (index, on-line model, reads q_des, k_tau, k_v, k_c)
        self._online: list[tuple[int, OnlineModel, bool, float, float, float]] = []
        self.extra_signals: tuple[str, ...] = ()  # signals besides tau and dq that the extra terms read
        motors = dict(getattr(motors, "models", motors))  # MotorParameters' `in` raises for unknown joints
        for j, g in gains.items():
            if j not in self.joint_names:
                raise ControlError(f'gains: joint "{j}" is not a robot joint: expected one of {list(self.joint_names)}')
            if j not in motors:
                raise ControlError(f'joint "{j}" has no motor model: expected one of {sorted(motors)}')
            i, m = self.joint_names.index(j), motors[j]
            issue = m.servo_issue()
            if issue is not None:
                raise ControlError(f'joint "{j}": motor model field \'{issue[0]}\' {issue[1]}')
            self.k_tau[i], self.k_v[i], self.k_c[i] = m.k_tau, m.k_v, m.k_c or 0.0
            self.k_p[i], self.k_i[i], self.integral_limit[i] = g.k_p, g.k_i, g.integral_limit
            if m.extra:
                om = online_model(j, m, self.period)
                self._online.append((i, om, "q_des" in om.signals, m.k_tau, m.k_v, m.k_c or 0.0))
                self.extra_signals += tuple(s for s in om.signals[2:] if s not in self.extra_signals)
        self.mask = np.isin(np.arange(n), [self.joint_names.index(j) for j in gains])
        # Clamp of the integral itself [N m s]; joints with k_i = 0 do not integrate.
        self._dt_integrates = (self.k_i > 0) * self.period
        self._i_max = np.divide(self.integral_limit, self.k_i, out=np.zeros(n), where=self.k_i > 0)
        self._i_min = -self._i_max
        self.has_integral = bool(np.any(self.k_i > 0))
        self._has_coulomb = bool(np.any(self.k_c > 0))
        # State and outputs, refreshed in place by update().
        self.integral = np.zeros(n)  # [N m s] integral of e_tau
        self.e_tau = np.zeros(n)  # [N m]
        self.tau_star = np.zeros(n)  # [N m] eq. 11
        self.integral_term = np.zeros(n)  # [N m] K_i integral(e_tau)
        self.friction = np.zeros(n)  # [rad] K_v dq_hat + k_c tanh(dq_hat / v_s)
        self.extra = np.zeros(n)  # [rad] extra motor-model terms (0 on joints without any)
        self.q_des_model = np.full(n, np.nan)  # [rad] the command the model's q_des history records
        self._ticks = 0
        self.dq_err = np.zeros(n)  # [rad] eq. 10
        self._tmp = np.zeros(n)

    @classmethod
    def from_config(cls, config: ControlConfig, period: float) -> JointTorqueController:
        return cls(config.joint_names, config.motors, config.gains, period, config.sign_velocity)

    def reset(self) -> None:
        """Empty the integral (on entering torque mode)."""
        self.integral.fill(0.0)
        self.integral_term.fill(0.0)

    def set_k_p(self, k_p: np.ndarray) -> None:
        """Write the torque gain ``k_p`` [-] (n,) in place (0 on joints without gains); the integral and its gain
        ``k_i`` are kept.

        Raises:
            ControlError: Not n finite numbers >= 0, or a nonzero gain on a joint without torque control (naming it).
        """
        k_p = np.asarray(k_p, dtype=float)
        if k_p.shape != self.k_p.shape:
            raise ControlError(f"k_p has shape {k_p.shape}: expected {self.k_p.shape}")
        bad = np.flatnonzero(~np.isfinite(k_p) | (k_p < 0) | (~self.mask & (k_p != 0)))
        if bad.size:
            i = int(bad[0])
            expected = "0 (a position-controlled joint)" if not self.mask[i] else "a finite number >= 0 [-]"
            raise ControlError(f"joint {self.joint_names[i]}: k_p = {float(k_p[i])!r}: expected {expected}")
        self.k_p[:] = k_p

    @property
    def has_extra(self) -> bool:
        """True if a joint's motor model has extra terms."""
        return bool(self._online)

    def update(self, tau_d: np.ndarray, tau_hat: np.ndarray, dq_hat: np.ndarray, q_hat: np.ndarray | None = None,
               ddq_hat: np.ndarray | None = None, time: float | None = None,
               dq_sign: np.ndarray | None = None) -> np.ndarray:
        """``dq_err`` (n,) [rad] for desired torques ``tau_d`` [N m], estimated torques ``tau_hat`` [N m] and
        velocities ``dq_hat`` [rad/s]; advances the integral and the extra terms' state by one period.

        Args:
            dq_hat: (n,) [rad/s] velocities the motor model reads: the estimated ones (the paper's eq. 10), or the
                reference's (ControlConfig.velocity_feedforward = "reference", passed by the control law).
            q_hat: (n,) [rad] estimated angles, needed by extra terms that read ``q`` or ``q_des``.
            ddq_hat: (n,) [rad/s^2] estimated accelerations, needed by ``elastic`` and ``backlash``.
            time: [s] robot time of the tick (default: ticks since construction times the period).
            dq_sign: (n,) [rad/s] velocities the direction-dependent terms read (Coulomb ``k_c`` and the extra
                terms; default ``dq_hat``): the reference's with ``velocity_feedforward = "reference_signs"``.

        Raises:
            ControlError: An extra term needs ``q_hat`` or ``ddq_hat`` and it was not given.
        """
        tmp = self._tmp
        np.subtract(tau_d, tau_hat, out=self.e_tau)
        # tau* = tau_d + K_p e_tau + K_i integral
        np.multiply(self.k_p, self.e_tau, out=self.tau_star)
        self.tau_star += tau_d
        if self.has_integral:
            # Anti-windup: integrate, then clamp |K_i integral| to integral_limit.
            np.multiply(self.e_tau, self._dt_integrates, out=tmp)
            self.integral += tmp
            np.clip(self.integral, self._i_min, self._i_max, out=self.integral)
            np.multiply(self.k_i, self.integral, out=self.integral_term)
            self.tau_star += self.integral_term
        # Friction feedforward: K_v dq + k_c tanh(dq_sign / v_s)
        dq_sign = dq_hat if dq_sign is None else dq_sign
        np.multiply(self.k_v, dq_hat, out=self.friction)
        if self._has_coulomb:
            np.multiply(dq_sign, 1.0 / self.sign_velocity, out=tmp)
            np.tanh(tmp, out=tmp)
            tmp *= self.k_c
            self.friction += tmp
        if self._online:
            self._update_extra(dq_sign, q_hat, ddq_hat, time)
        # dq_err = K_tau tau* + friction + extra
        np.multiply(self.k_tau, self.tau_star, out=self.dq_err)
        self.dq_err += self.friction
        if self._online:
            self.dq_err += self.extra
        self._ticks += 1
        return self.dq_err

    def _update_extra(self, dq_sign, q_hat, ddq_hat, time) -> None:
        """``extra`` [rad]: the on-line model at (tau*, dq_sign, ...) minus its linear and Coulomb part."""
        if q_hat is None and ("q" in self.extra_signals or "q_des" in self.extra_signals):
            raise ControlError(f"q_hat is None: expected (n,) angles [rad] for the extra motor-model terms "
                               f"(they read {list(self.extra_signals)})")
        if ddq_hat is None and "ddq" in self.extra_signals:
            raise ControlError(f"ddq_hat is None: expected (n,) accelerations [rad/s^2] for the extra motor-model "
                               f"terms (they read {list(self.extra_signals)})")
        t = self._ticks * self.period if time is None or time != time else float(time)  # NaN: not set
        for i, om, reads_q_des, k_tau, k_v, k_c in self._online:
            tau, dq = float(self.tau_star[i]), float(dq_sign[i])
            q = None if q_hat is None else float(q_hat[i])
            ddq = None if ddq_hat is None else float(ddq_hat[i])
            if reads_q_des:
                q_des = om.command(q, tau, dq, t=t, ddq=ddq)
                model = q_des - q
            else:
                model = om.step(tau, dq, q=q, t=t, ddq=ddq)
                q_des = math.nan if q is None else q + model
            self.q_des_model[i] = q_des
            coulomb = k_c * (1.0 if dq > 0 else -1.0 if dq < 0 else 0.0)
            self.extra[i] = model - (k_tau * tau + k_v * dq + coulomb)


def online_model(joint: str, m: MotorModel, period: float) -> OnlineModel:
    """The on-line model of ``joint``, checked on one sample of every signal.

    Raises:
        ControlError: An extra term or its shape parameters cannot be evaluated (named with the joint).
    """
    try:
        return checked_online_model(m, period)
    except IdentificationError as err:
        raise ControlError(f'joint "{joint}": {err}') from err
