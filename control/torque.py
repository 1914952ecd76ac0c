"""Joint-torque controller of the paper (eq. 10-11): desired torques -> position-error command.

::

    tau*   = tau_d + K_p e_tau + K_i integral(e_tau) dt,   e_tau = tau_d - tau_hat      (eq. 11)
    dq_err = K_tau tau* + K_v dq_hat [+ k_c tanh(dq_hat / v_s)] [+ extra effects]          (eq. 10)
    q_des  = q + dq_err                                     (the servo only takes desired angles)

``K_tau``, ``K_v``, ``k_c`` are the identified motor model (:class:`~servotau.identification.MotorModel`).
The integral is clamped so that ``|K_i integral| <= integral_limit`` (anti-windup). Extra effect terms of a
motor model are used when the model can evaluate them (``MotorModel.predict`` accepts them); otherwise they
are ignored, listed in :attr:`JointTorqueController.ignored_effects` and logged once.

Joints without gains (position-controlled) have every gain at 0: their outputs are 0.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

import numpy as np

from servotau.errors import ControlError, IdentificationError
from servotau.identification.motor_params import MotorModel

from .config import ControlConfig, JointGains

log = logging.getLogger(__name__)


class JointTorqueController:
    """Eq. 10-11 vectorised over the joints, without allocation per tick."""

    def __init__(self, joint_names: Sequence[str], motors: Mapping[str, MotorModel], gains: Mapping[str, JointGains],
                 period: float, sign_velocity: float = 0.01):
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
        self._extra: list[tuple[int, MotorModel]] = []
        self.ignored_effects: dict[str, list[str]] = {}
        motors = dict(getattr(motors, "models", motors))  # MotorParameters' `in` raises for unknown joints
        for j, g in gains.items():
            if j not in self.joint_names:
                raise ControlError(f'gains: joint "{j}" is not a robot joint: expected one of {list(self.joint_names)}')
            if j not in motors:
                raise ControlError(f'joint "{j}" has no motor model: expected one of {sorted(motors)}')
            i, m = self.joint_names.index(j), motors[j]
            self.k_tau[i], self.k_v[i], self.k_c[i] = m.k_tau, m.k_v, m.k_c or 0.0
            self.k_p[i], self.k_i[i], self.integral_limit[i] = g.k_p, g.k_i, g.integral_limit
            if m.extra:
                try:
                    m.predict(np.zeros(1), np.zeros(1))
                    self._extra.append((i, m))
                except (IdentificationError, TypeError, ValueError):
                    self.ignored_effects[j] = list(m.extra)
        if self.ignored_effects:
            log.warning("motor-model extra terms the model cannot evaluate are ignored (linear model used): %s",
                        self.ignored_effects)
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
        self.friction = np.zeros(n)  # [rad] K_v dq_hat + k_c tanh(dq_hat / v_s) + extra
        self.dq_err = np.zeros(n)  # [rad] eq. 10
        self._tmp = np.zeros(n)

    @classmethod
    def from_config(cls, config: ControlConfig, period: float) -> JointTorqueController:
        return cls(config.joint_names, config.motors, config.gains, period, config.sign_velocity)

    def reset(self) -> None:
        """Empty the integral (on entering torque mode)."""
        self.integral.fill(0.0)
        self.integral_term.fill(0.0)

    def update(self, tau_d: np.ndarray, tau_hat: np.ndarray, dq_hat: np.ndarray) -> np.ndarray:
        """``dq_err`` (n,) [rad] for desired torques ``tau_d`` [N m], estimated torques ``tau_hat`` [N m] and
        estimated velocities ``dq_hat`` [rad/s]; advances the integral by one period."""
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
        # Friction feedforward: K_v dq + k_c tanh(dq / v_s)
        np.multiply(self.k_v, dq_hat, out=self.friction)
        if self._has_coulomb:
            np.multiply(dq_hat, 1.0 / self.sign_velocity, out=tmp)
            np.tanh(tmp, out=tmp)
            tmp *= self.k_c
            self.friction += tmp
        for i, m in self._extra:  # extra effect terms: what predict() adds to the linear model
            tau_i, dq_i = self.tau_star[i : i + 1], np.asarray(dq_hat)[i : i + 1]
            linear = m.k_tau * tau_i[0] + m.k_v * dq_i[0] + (m.k_c or 0.0) * np.sign(dq_i[0])
            self.friction[i] += float(m.predict(tau_i, dq_i)[0]) - linear
        # dq_err = K_tau tau* + friction
        np.multiply(self.k_tau, self.tau_star, out=self.dq_err)
        self.dq_err += self.friction
        return self.dq_err
