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

Gains change during a run (a task's phases, :meth:`TorqueControlLaw.set_gains`) in place, in the law's own arrays
(:class:`ControlTerms` shares them by identity: nothing is reallocated). In torque mode a change is ramped over
``ramp`` [s] (half-cosine from the old to the new ``K_p``, ``K_s``, ``K_d``), so the command has no step at a phase
boundary: each tick it moves by what the gains of that tick imply from the same state. Entering torque mode
(:meth:`TorqueControlLaw.reset`) completes a ramp at once (the manager's bumpless switch fades the whole command
then). The integrals keep their state across a change: the torque integral (``K_i`` is not a phase gain) and the
position integral ``i_q`` [rad], whose torque ``K_s i_q`` follows the stiffness as it ramps.
"""


from __future__ import annotations

import math

import numpy as np

from servotau.errors import ControlError
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
        n = len(config.joint_names)
        self._tmp = np.zeros(n)
        self._ramp_from = np.zeros((3, n))  # (k_p, k_s, k_d) at a ramp's start
        self._ramp_to = np.zeros((3, n))  # ... and at its end
        self._ramp_ticks = 0  # ticks of the ramp in progress
        self._ramp_k = 0  # ticks done (== _ramp_ticks: no ramp)
        self._period = float(period)

    @property
    def gains(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The gains in use ``(k_p [-], k_s [N m/rad], k_d [N m s/rad])``, each (n,) (the law's arrays, read-only
        views)."""
        out = []
        for a in (self.torque.k_p, self.inverse_dynamics.k_s, self.inverse_dynamics.k_d):
            v = a.view()
            v.flags.writeable = False
            out.append(v)
        return tuple(out)

    def set_gains(self, k_p, k_s, k_d, ramp: float = 0.0) -> None:
        """Change ``K_p`` [-], ``K_s`` [N m/rad] and ``K_d`` [N m s/rad] (each (n,), 0 on position-controlled joints)
        in place, from the next :meth:`update` on, ramped over ``ramp`` [s] (module doc; 0: at once).

        Raises:
            ControlError: A gain is not a finite number >= 0, or nonzero on a position-controlled joint (naming the
                joint and the gain); nothing is changed then.
        """
        names, mask, n = self.config.joint_names, self.torque.mask, len(self.config.joint_names)
        target = np.empty((3, n))
        for row, (name, value, unit) in enumerate((("k_p", k_p, "-"), ("k_s", k_s, "N m/rad"),
                                                    ("k_d", k_d, "N m s/rad"))):
            arr = np.asarray(value, dtype=float)
            if arr.shape != (n,):
                raise ControlError(f"set_gains: {name} has shape {arr.shape}: expected ({n},) [{unit}]")
            bad = np.flatnonzero(~np.isfinite(arr) | (arr < 0) | (~mask & (arr != 0)))
            if bad.size:
                i = int(bad[0])
                expected = "0 (a position-controlled joint)" if not mask[i] else f"a finite number >= 0 [{unit}]"
                raise ControlError(f"set_gains: joint {names[i]}: {name} = {float(arr[i])!r}: expected {expected}")
            target[row] = arr
        if not (ramp >= 0 and np.isfinite(ramp)):
            raise ControlError(f"set_gains: ramp = {ramp!r}: expected a finite number >= 0 [s]")
        np.copyto(self._ramp_to, target)
        self._ramp_from[0], self._ramp_from[1], self._ramp_from[2] = self.gains
        self._ramp_ticks, self._ramp_k = int(round(ramp / self._period)), 0
        if self._ramp_ticks == 0:
            self._apply(self._ramp_to)

    def _apply(self, g: np.ndarray) -> None:
        """Write gains ``g`` = (k_p, k_s, k_d) rows into every array that depends on them (no allocation)."""
        tc, idc = self.torque, self.inverse_dynamics
        tc.set_k_p(g[0])
        idc.set_gains(g[1], g[2])
        np.copyto(self.position_integral.k_s, g[1])
        np.multiply(tc.k_tau, tc.k_p, out=self._kt_kp)
        np.add(tc.k_p, 1.0, out=self._kt_1kp)
        self._kt_1kp *= tc.k_tau
        np.multiply(self._kt_1kp, idc.k_s, out=self.k6)
        np.multiply(self._kt_1kp, idc.k_d, out=self.k7)

    def _ramp_step(self) -> None:
        self._ramp_k += 1
        w = 0.5 * (1.0 - math.cos(math.pi * self._ramp_k / self._ramp_ticks))  # 0 -> 1
        g = self._ramp_from + w * (self._ramp_to - self._ramp_from) if self._ramp_k < self._ramp_ticks \
            else self._ramp_to
        self._apply(g)

    def make_terms(self) -> ControlTerms:
        """The outputs holder this law writes into (it shares the law's own buffers: no copy per tick)."""
        idc, tc = self.inverse_dynamics, self.torque
        shared = {"tau_d": idc.tau_d, "e_q": idc.e_q, "de_q": idc.de_q, "dde_q": idc.dde_q, "f_d": idc.f_d,
                  "f_hat": idc.f_hat, "e_f": idc.e_f, "tau_star": tc.tau_star, "e_tau": tc.e_tau}
        return ControlTerms(len(self.config.joint_names), shared)

    def reset(self) -> None:
        """Empty the torque and position integrals and complete a gain ramp (on entering torque mode)."""
        if self._ramp_k < self._ramp_ticks:
            self._ramp_k = self._ramp_ticks
            self._apply(self._ramp_to)
        self.torque.reset()
        self.position_integral.reset()

    def update(self, terms: ControlTerms, q_hat, dq_hat, ddq_hat, tau_hat, q_d, dq_d, ddq_d, wrenches=None,
               base: BaseState | None = None, q_encoder=None) -> np.ndarray:
        """Compute the law and write every torque component into ``terms`` (from :meth:`make_terms`); return
        ``dq_err`` (n,) [rad]. ``q_encoder``: the frame's measured angles [rad], read by the position error
        ``e_q = q_d - q`` instead of ``q_hat`` when ``position_feedback = "encoder"`` (None: q_hat)."""
        if self._ramp_k < self._ramp_ticks:
            self._ramp_step()
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
