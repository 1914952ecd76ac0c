"""Model-based prediction of the joint torque to the frame time (beyond the paper, its section 6 idea).

The SG estimate is accurate but late by the filter delay ``D``. The actuator model of the paper
(eq. 6 without the Coulomb term), ``q_des - q = k_tau tau + k_v dq``, gives a zero-delay but
biased torque ``m(t) = (q_des - q - k_v dq) / k_tau`` (``dq`` from a short causal SG evaluated at the
newest sample). The predictor keeps the model's fast part and the estimator's accuracy::

    tau_pred(t) = m(t) + [tau_sg - m_sg](t - D)

where ``m_sg`` is ``m`` passed through the same filter as the encoders (same window, order and
evaluation point, same alignment delay), so that the bracket is the model's error seen with the
estimator's delay. A constant model bias cancels exactly; what remains is the change of the model
error over ``D`` (friction reversals, unmodelled dynamics) and the noise of ``m``.

Timing (as the servo computes its current): ``q_des`` passed with a frame is the command applied
during the period that ended at that frame, and the position error uses the encoder reading at the
start of that period (the previous frame), as does the velocity:
``q_des(k) - q(k - 1) = k_tau tau(k) + k_v dq(k - 1)``. Identify ``k_tau`` and ``k_v`` with the same pairing.
"""

from __future__ import annotations

import numpy as np

from servotau.errors import EstimationError
from servotau.signal.savgol import CausalSavgol

from .config import PredictionSettings
from .delay_line import DelayLine


class ModelPredictor:
    """Preallocated predictor for the joints that have motor parameters.

    Args:
        joint_names: HAL joint order.
        settings: Motor parameters per joint name and the velocity window.
        dt: Sampling period [s].
        window, order, eval_at: Settings of the estimator's encoder filter (``m_sg`` uses them).
        align_delay: Extra input delay of the encoder filter [samples] (time alignment).
    """

    def __init__(self, joint_names: tuple[str, ...], settings: PredictionSettings, dt: float, window: int,
                 order: int, eval_at: str, align_delay: int):
        unknown = sorted(set(settings.k_tau) - set(joint_names))
        if unknown:
            raise EstimationError(f"prediction: joints {unknown} are not in RobotInfo.joint_names")
        self.joints = np.array([i for i, j in enumerate(joint_names) if j in settings.k_tau], dtype=np.intp)
        names = [joint_names[i] for i in self.joints]
        self.k_tau = np.array([settings.k_tau[j] for j in names])  # [rad/(N m)]
        self.k_v = np.array([settings.k_v[j] for j in names])  # [rad s/rad]
        n = len(self.joints)
        self.n = n
        self._velocity = CausalSavgol(max(n, 1), settings.velocity_window, 2, dt, derivs=(1,), eval_at="last")
        self._m_filter = CausalSavgol(max(n, 1), window, order, dt, derivs=(0,), eval_at=eval_at)
        self._line = DelayLine(max(n, 1), align_delay)
        self._q = np.zeros(n)  # angles of the previous frame until update() pushes the new ones
        self._m = np.zeros(n)
        self._have_m = False
        self._fresh = False
        self._m_count = 0  # model torques pushed since the velocity filter became ready
        self._flush = window + align_delay
        self._t = np.zeros(n)

    @property
    def ready(self) -> bool:
        """True once the filter of ``m`` holds only model torques."""
        return self._m_count >= self._flush

    def update(self, q: np.ndarray, q_des: np.ndarray | None) -> None:
        """Push the held encoder angles ``q`` (n_all,) [rad] and the command ``q_des`` (n_all,) [rad].

        Without a command, the last model torque is repeated (the prediction is then invalid).
        """
        if self.n == 0:
            return
        # The servo computed its current from the previous frame's angle and velocity: use them, then
        # push this frame's angle.
        if q_des is not None:
            q_des = np.asarray(q_des, dtype=float)
            if q_des.shape != q.shape or not np.all(np.isfinite(q_des)):
                raise EstimationError(f"q_des: expected {q.shape} finite angles [rad], got shape {q_des.shape}")
            if self._velocity.ready:
                m, t = self._m, self._t
                np.take(q_des, self.joints, out=m)
                m -= self._q
                np.multiply(self.k_v, self._velocity.outputs[0], out=t)
                m -= t
                m /= self.k_tau
                self._have_m = True
                if self._m_count < self._flush:
                    self._m_count += 1
        np.take(q, self.joints, out=self._q)
        self._velocity.update(self._q)
        self._fresh = q_des is not None and self._have_m
        self._m_filter.update(self._line.push(self._m))

    def predict(self, tau_sg: np.ndarray, out: np.ndarray) -> None:
        """``out[joints] = m + tau_sg[joints] - m_sg``; NaN elsewhere or when not ready."""
        out.fill(np.nan)
        if self.n == 0 or not (self.ready and self._fresh):
            return
        t = self._t
        np.take(tau_sg, self.joints, out=t)
        t -= self._m_filter.outputs[0]
        t += self._m
        out[self.joints] = t
