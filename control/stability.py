"""The torque loop's stability predicted from the identified motor model (issue 22): one joint, linearised.

One joint of inertia ``J`` [kg m^2] (link and rotor, at the reference posture) driven by its position servo as the
identified model says (paper eq. 6: ``tau = (dq_err - k_v dq) / k_tau``, the servo's damping integrated implicitly
as the simulator does), read every period ``T`` by the estimator's last-sample Savitzky-Golay filters (window,
order of the ``low_delay`` variant: the encoders' dq_hat and ddq_hat, ``tau_hat = J ddq_hat``), and commanded by the
paper's law at a resting reference (eq. 10-12, gravity and friction aside)::

    tau*   = (1 + K_p) (-K_s q - K_d dq_hat) - K_p J ddq_hat
    dq_err = k_tau tau* + k_v dq_hat

The closed loop is linear in ``(q[k], ..., q[k - W + 1], dq[k])``; its spectral radius ``rho`` says whether the
loop is stable (``rho < 1``) and by how much (``1 - rho``, per period). A servo that is not what the model says
(``true_scale``: its k_tau and k_v relative to the model's) moves rho; :func:`worst_radius` takes the largest over
a set of such servos, the margin a tuning needs on servos it was not identified on.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from servotau.errors import ControlError

# (k_tau, k_v) of the true servo relative to the model's: the asymmetric fit under-estimates both by up to ~20 %
# (docs/identification.md), and a servo drifts; the tuning must hold on all of them.
MISMATCH = ((1.0, 1.0), (1.25, 1.25), (1.25, 0.8), (0.85, 1.2), (0.85, 0.85))


@dataclass(frozen=True)
class LoopModel:
    """One joint's loop: the identified model, the inertia and the estimator's filters."""

    k_tau: float  # [rad/(N m)] identified
    k_v: float  # [rad/(rad/s)] identified
    inertia: float  # [kg m^2] link and rotor at the reference posture
    period: float  # [s]
    window: int  # [samples] of the estimator's encoder filter
    order: int  # of the encoder filter

    def __post_init__(self) -> None:
        for name, unit in (("k_tau", "rad/(N m)"), ("inertia", "kg m^2"), ("period", "s")):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ControlError(f"LoopModel.{name} = {v!r}: expected a finite number > 0 [{unit}]")
        if not (np.isfinite(self.k_v) and self.k_v >= 0):
            raise ControlError(f"LoopModel.k_v = {self.k_v!r}: expected a finite number >= 0 [rad/(rad/s)]")
        if self.window <= self.order + 1:
            raise ControlError(f"LoopModel.window = {self.window}: expected more than order + 1 = {self.order + 1}")


def _filters(window: int, order: int, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Last-sample Savitzky-Golay first and second derivatives as FIR taps on ``q[k - i]``, ``i = 0 .. W-1``."""
    from scipy.signal import savgol_coeffs

    d1 = savgol_coeffs(window, order, deriv=1, delta=period, pos=window - 1, use="dot")[::-1]
    d2 = savgol_coeffs(window, order, deriv=2, delta=period, pos=window - 1, use="dot")[::-1]
    return d1, d2


def transition(m: LoopModel, k6: float, k7: float, k_p: float, true_scale: tuple[float, float] = (1.0, 1.0)
               ) -> np.ndarray:
    """The closed loop's transition matrix on ``(q[k], ..., q[k - W + 1], dq[k])`` for the servo-side gains
    ``k6`` [-], ``k7`` [s] (paper 4.2: ``K_s = k6 / (k_tau (1 + K_p))``, ``K_d = k7 / (k_tau (1 + K_p))``)."""
    w, t = m.window, m.period
    d1, d2 = _filters(w, m.order, t)
    kt_true, kv_true = m.k_tau * true_scale[0], m.k_v * true_scale[1]
    kp_true, damp_true = 1.0 / kt_true, kv_true / kt_true
    # dq_err as a row over the state: k_tau (1 + K_p)(-K_s q - K_d dq_hat) - k_tau K_p J ddq_hat + k_v dq_hat
    cmd = np.zeros(w + 1)
    cmd[0] -= k6
    cmd[:w] += -k7 * d1 - m.k_tau * k_p * m.inertia * d2 + m.k_v * d1
    a = np.zeros((w + 1, w + 1))
    # dq[k+1] = (dq[k] + T kp cmd / J) / (1 + T D / J): the servo's damping implicit, as simrobot integrates it
    den = 1.0 + t * damp_true / m.inertia
    dq_row = (t * kp_true / m.inertia) * cmd
    dq_row[w] += 1.0
    dq_row /= den
    a[w] = dq_row
    a[0] = t * dq_row
    a[0, 0] += 1.0
    a[1:w, 0:w - 1] = np.eye(w - 1)
    return a


def spectral_radius(a: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(a))))


def radius(m: LoopModel, k6: float, k7: float, k_p: float, true_scale: tuple[float, float] = (1.0, 1.0)) -> float:
    """Spectral radius of the closed loop (< 1: stable)."""
    return spectral_radius(transition(m, k6, k7, k_p, true_scale))


def worst_radius(m: LoopModel, k6: float, k7: float, k_p: float,
                 mismatch: Iterable[tuple[float, float]] = MISMATCH) -> float:
    """The largest spectral radius over servos that differ from the model by ``mismatch``."""
    return max(radius(m, k6, k7, k_p, s) for s in mismatch)
