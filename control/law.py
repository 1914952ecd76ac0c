"""The complete torque-control law: inverse dynamics (eq. 12) then torque feedback and motor model (eq. 10-11),
with the command split into the paper's components (eq. 13-14, section 5.5).

With ``b = M ddq + h``, ``tau_m = b_hat - J^T f_hat`` (the model's torque for the estimated motion) and
``r = tau_hat - tau_m`` (what the estimator's torque adds to the model)::

    dq_err = K_tau tau* + ff_friction + ff_extra                (eq. 10, motor model: control/torque.py)

    K_tau tau* = K_tau (b_d - J^T f_ff)                         ff_torque
               + K_tau (1 + K_p) K_s e_q                        fb_position      (K6 e_q)
               + K_tau (1 + K_p) K_d de_q                       fb_velocity      (K7 de_q)
               + K_tau K_p (b_d - b_hat)                        fb_acceleration  (K8 dde_q)
               - K_tau (K_p J^T e_f + (1 + K_p) J^T K_f e_f)    fb_force         (K9 e_f)
               - K_tau K_p r                                    fb_torque_residual
               + K_tau K_i integral(e_tau)                      fb_integral
               + K_tau (1 + K_p) tau_iq                         fb_position_integral (not in the paper)

which is exact (not an approximation): the components always sum to the command ``dq_err``.

The motor-model feedforward (``ff_friction``, ``ff_extra``) reads the velocity ``dq_ff`` chosen by
``velocity_feedforward``: ``estimate`` is the paper's ``dq_hat``; ``reference`` is ``dq_d``, free of the
estimator's noise and delay (then ``K_v (dq_d - dq_hat)``, the servo's own damping, is left as velocity feedback
besides K7); ``reference_signs`` keeps the paper's ``K_v dq_hat`` and takes from ``dq_d`` only the direction of
motion that the Coulomb and extra terms switch on (a noisy, delayed ``dq_hat`` flips them at rest). The feedback
terms always read the estimates.

``tau_d`` is eq. 12 plus ``tau_iq``, the integral of the position error while the reference is at rest, kept out
of the force task's directions (control/position_integral.py; 0 unless a joint has ``k_iq`` > 0).
"""

from __future__ import annotations

import numpy as np

from servotau.hal.types import RobotInfo

from .config import ControlConfig
from .dynamics import BaseState
from .inverse_dynamics import InverseDynamics
from .position_integral import PositionIntegral
from .terms import TORQUE_COMPONENTS, ControlTerms
from .torque import JointTorqueController


class TorqueControlLaw:
    """Eq. 10-12 for every joint (gains 0 on position-controlled joints), outputs in a :class:`ControlTerms`."""

    def __init__(self, config: ControlConfig, model_path: str, period: float, info: RobotInfo | None = None):
        """``info``: the robot's root joint and F/T sensor frames (None: those of :mod:`servotau.description`)."""
        self.config = config
        self.inverse_dynamics = InverseDynamics.from_config(config, model_path, info)
        self.torque = JointTorqueController.from_config(config, period)
        self.position_integral = PositionIntegral(self.inverse_dynamics.k_s, config.joint_vector("k_iq"),
                                                  config.joint_vector("position_integral_limit"),
                                                  config.rest_velocity, period)
        tc = self.torque
        self.k6 = tc.k_tau * (1.0 + tc.k_p) * self.inverse_dynamics.k_s  # [-]
        self.k7 = tc.k_tau * (1.0 + tc.k_p) * self.inverse_dynamics.k_d  # [s]
        self._ff_velocity = config.velocity_feedforward
        self._encoder_position = config.position_feedback == "encoder"
        self._kt_kp = tc.k_tau * tc.k_p
        self._kt_1kp = tc.k_tau * (1.0 + tc.k_p)
        self._tmp = np.zeros(len(config.joint_names))

    def make_terms(self) -> ControlTerms:
        """The outputs holder this law writes into (it shares the law's own buffers: no copy per tick)."""
        idc, tc = self.inverse_dynamics, self.torque
        shared = {"tau_d": idc.tau_d, "e_q": idc.e_q, "de_q": idc.de_q, "dde_q": idc.dde_q, "f_d": idc.f_d,
                  "f_hat": idc.f_hat, "e_f": idc.e_f, "tau_star": tc.tau_star, "e_tau": tc.e_tau}
        return ControlTerms(len(self.config.joint_names), shared)

    def reset(self) -> None:
        """Empty the torque and position integrals (on entering torque mode)."""
        self.torque.reset()
        self.position_integral.reset()

    def update(self, terms: ControlTerms, q_hat, dq_hat, ddq_hat, tau_hat, q_d, dq_d, ddq_d, wrenches=None,
               base: BaseState | None = None, q_encoder=None) -> np.ndarray:
        """Compute the law and write every torque component into ``terms`` (from :meth:`make_terms`); return
        ``dq_err`` (n,) [rad]. ``q_encoder``: the frame's measured angles [rad], read by the position error
        ``e_q = q_d - q`` instead of ``q_hat`` when ``position_feedback = "encoder"`` (None: q_hat)."""
        idc, tc, t, tmp = self.inverse_dynamics, self.torque, terms, self._tmp
        tau_d = idc.update(q_hat, dq_hat, ddq_hat, q_d, dq_d, ddq_d, wrenches, base)
        if self._encoder_position and q_encoder is not None:  # e_q = q_d - q: add K_s (q_hat - q) to tau_d
            np.subtract(q_hat, q_encoder, out=tmp)
            idc.e_q += tmp
            tmp *= idc.k_s
            tau_d += tmp
        pint = self.position_integral
        if pint.active:
            tau_d += pint.update(idc.e_q, dq_d, idc.task_jacobian)
        dq_ff = dq_d if self._ff_velocity == "reference" else dq_hat
        dq_sign = dq_d if self._ff_velocity == "reference_signs" else None
        dq_err = tc.update(tau_d, tau_hat, dq_ff, q_hat, ddq_hat, t.time, dq_sign)
        np.multiply(tc.k_tau, idc.tau_ff, out=t.ff_torque)
        np.copyto(t.ff_friction, tc.friction)
        np.copyto(t.ff_extra, tc.extra)
        np.multiply(self.k6, idc.e_q, out=t.fb_position)
        np.multiply(self.k7, idc.de_q, out=t.fb_velocity)
        np.subtract(idc.b_d, idc.b_hat, out=tmp)
        np.multiply(self._kt_kp, tmp, out=t.fb_acceleration)
        if idc.force is not None:
            np.multiply(self._kt_kp, idc.jt_ef, out=t.fb_force)
            np.multiply(self._kt_1kp, idc.jt_kf_ef, out=tmp)
            t.fb_force += tmp
            np.negative(t.fb_force, out=t.fb_force)
        np.subtract(idc.b_hat, idc.jtf_hat, out=tmp)  # tau_m
        tmp -= tau_hat  # -r
        np.multiply(self._kt_kp, tmp, out=t.fb_torque_residual)
        if tc.has_integral:
            np.multiply(tc.k_tau, tc.integral_term, out=t.fb_integral)
        if pint.active:
            np.multiply(self._kt_1kp, pint.tau, out=t.fb_position_integral)
        np.copyto(t.tau_hat, tau_hat)
        return dq_err

    @staticmethod
    def clear(terms: ControlTerms) -> None:
        """Zero the torque components (outside torque mode)."""
        for name in TORQUE_COMPONENTS:
            getattr(terms, name).fill(0.0)
