"""The torque loop's stability predicted from the identified motor model (issue 22): one joint, linearised.

One joint of inertia ``J`` [kg m^2] (link and rotor, at the reference posture) driven by its position servo as the
identified model says (paper eq. 6: ``tau = (dq_err - k_v dq) / k_tau``, the servo's damping integrated implicitly
as the simulator does), read every period ``T`` by the estimator's last-sample Savitzky-Golay filters (window,
order of the ``low_delay`` variant: ``S0``, ``S1``, ``S2`` give q_hat, dq_hat, ddq_hat from the encoder), and
commanded by the paper's law at a resting reference (eq. 10-12, gravity and friction aside)::

    tau*   = (1 + K_p) (-K_s q_hat - K_d dq_hat - c_ft J^T f_hat) - K_p tau_hat
    tau_hat = (J - J_f) ddq_hat + J_f F[ddq]          J^T f_hat = J_f (ddq_hat - F[ddq])
    dq_err = k_tau tau* + k_v dq_hat

What the loop's signals carry that a plain ``J ddq_hat`` leaves out, and which sets the K6 = 1 trip of servos
with little damping (a ~20 Hz oscillation that grows):

- **The position error reads q_hat**, not the encoder: the last-sample order-3 filter over 80 samples amplifies
  15-25 Hz by up to 2x with a phase lag (39 deg at 20 Hz), so at K6 = 1 the position feedback is a second servo
  stiffness with a lag, i.e. negative damping near the joint's resonance (``K6 |S0| sin(phase) / (k_tau w)``:
  about 100 N m s/rad on a hip pitch whose servo damping is 39).
- **The F/T path**: the estimator adds the inertial wrench of the body beyond an F/T sensor (the foot, inertia
  ``J_f`` about the joint) from the encoders (``S2``, order 3) to the measured wrench, which passes the F/T filter
  ``F`` (order 1). The two disagree above a few Hz, and the controller feeds the difference back with gain 1: the
  contact term ``-J^T f_hat`` of tau_d ((1 + K_p) times) and the measured wrench inside tau_hat (``-K_p`` times)
  leave ``J_f (F[ddq] - S2[q])`` (``c_ft = 1``); without the contact term, ``-K_p`` times that. At 20 Hz this
  is a delayed positive acceleration feedback: less inertia (the frequency rises from ~14 to ~20 Hz) and
  negative damping.

The closed loop is linear in ``(q[k], ..., q[k - W + 1], dq[k], a[k], ..., a[k - W_f + 1])`` (``a``: the
acceleration the F/T sensor feels, ``(dq[k] - dq[k-1]) / T``); its spectral radius ``rho`` says whether the loop
is stable (``rho < 1``) and by how much (``1 - rho``, per period). A servo that is not what the model says
(``true_scale``: its k_tau and k_v relative to the model's) moves rho; :func:`worst_radius` takes the largest over
a set of such servos, the margin a tuning needs on servos it was not identified on.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from servotau.errors import ControlError
from servotau.signal.savgol import savgol_coeffs

# (k_tau, k_v) of the true servo relative to the model's: the asymmetric fit under-estimates both by up to ~20 %
# (docs/identification.md), and a servo drifts; the tuning must hold on all of them.
MISMATCH = ((1.0, 1.0), (1.25, 1.25), (1.25, 0.8), (0.85, 1.2), (0.85, 0.85))


@dataclass(frozen=True)
class LoopModel:
    """One joint's loop: the identified model, the inertias and the estimator's filters."""

    k_tau: float  # [rad/(N m)] identified
    k_v: float  # [rad/(rad/s)] identified
    inertia: float  # [kg m^2] link and rotor at the reference posture
    period: float  # [s]
    window: int  # [samples] of the estimator's encoder filter
    order: int  # of the encoder filter
    ft_inertia: float = 0.0  # [kg m^2] J_f: share of `inertia` beyond an F/T sensor (the foot), 0: none
    ft_window: int = 80  # [samples] of the estimator's F/T filter
    ft_order: int = 1  # of the F/T filter
    contact: bool = True  # the law's tau_d holds -J^T f_hat of that sensor (control.toml `contacts`)
    encoder_position: bool = False  # the position error reads the encoder's q, not q_hat (ControlConfig)

    def __post_init__(self) -> None:
        for name, unit in (("k_tau", "rad/(N m)"), ("inertia", "kg m^2"), ("period", "s")):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ControlError(f"LoopModel.{name} = {v!r}: expected a finite number > 0 [{unit}]")
        if not (np.isfinite(self.k_v) and self.k_v >= 0):
            raise ControlError(f"LoopModel.k_v = {self.k_v!r}: expected a finite number >= 0 [rad/(rad/s)]")
        if self.window <= self.order + 1:
            raise ControlError(f"LoopModel.window = {self.window}: expected more than order + 1 = {self.order + 1}")
        if not (np.isfinite(self.ft_inertia) and 0 <= self.ft_inertia <= self.inertia):
            raise ControlError(f"LoopModel.ft_inertia = {self.ft_inertia!r}: expected a number in [0, inertia = "
                               f"{self.inertia:g}] [kg m^2]")
        if self.ft_inertia > 0 and self.ft_window <= self.ft_order:
            raise ControlError(f"LoopModel.ft_window = {self.ft_window}: expected more than ft_order = "
                               f"{self.ft_order}")


@lru_cache(maxsize=16)
def _taps(window: int, order: int, deriv: int, period: float) -> np.ndarray:
    """Last-sample Savitzky-Golay ``deriv``-th derivative as FIR taps on ``x[k - i]``, ``i = 0 .. W-1``."""
    c = savgol_coeffs(window, order, deriv=deriv, delta=period, pos=window - 1, use="dot")[::-1].copy()
    c.setflags(write=False)
    return c


def _filters(window: int, order: int, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Last-sample Savitzky-Golay first and second derivatives as FIR taps on ``q[k - i]``, ``i = 0 .. W-1``."""
    return _taps(window, order, 1, period), _taps(window, order, 2, period)


def transition(m: LoopModel, k6: float, k7: float, k_p: float, true_scale: tuple[float, float] = (1.0, 1.0)
               ) -> np.ndarray:
    """The closed loop's transition matrix on ``(q[k], ..., q[k - W + 1], dq[k][, a[k], ..., a[k - W_f + 1]])``
    for the servo-side gains ``k6`` [-], ``k7`` [s] (paper 4.2: ``K_s = k6 / (k_tau (1 + K_p))``,
    ``K_d = k7 / (k_tau (1 + K_p))``)."""
    w, t = m.window, m.period
    s0, d1, d2 = _taps(w, m.order, 0, t), _taps(w, m.order, 1, t), _taps(w, m.order, 2, t)
    wf = m.ft_window if m.ft_inertia > 0 else 0
    n = w + 1 + wf
    kt_true, kv_true = m.k_tau * true_scale[0], m.k_v * true_scale[1]
    kp_true, damp_true = 1.0 / kt_true, kv_true / kt_true
    # dq_err as a row over the state: -K6 q_hat + (k_v - K7) dq_hat - k_tau K_p J ddq_hat + F/T path
    cmd = np.zeros(n)
    cmd[:w] += (m.k_v - k7) * d1 - m.k_tau * k_p * m.inertia * d2
    if m.encoder_position:
        cmd[0] -= k6
    else:
        cmd[:w] -= k6 * s0
    if wf:
        c_ft = 1.0 if m.contact else -k_p
        cmd[:w] -= c_ft * m.k_tau * m.ft_inertia * d2
        cmd[w + 1:] += c_ft * m.k_tau * m.ft_inertia * _taps(wf, m.ft_order, 0, t)
    a = np.zeros((n, n))
    # dq[k+1] = (dq[k] + T kp cmd / J) / (1 + T D / J): the servo's damping implicit, as simrobot integrates it
    den = 1.0 + t * damp_true / m.inertia
    dq_row = (t * kp_true / m.inertia) * cmd
    dq_row[w] += 1.0
    dq_row /= den
    a[w] = dq_row
    a[0] = t * dq_row
    a[0, 0] += 1.0
    a[1:w, 0:w - 1] = np.eye(w - 1)
    if wf:  # the F/T sensor feels a[k+1] = (dq[k+1] - dq[k]) / T
        a[w + 1] = dq_row / t
        a[w + 1, w] -= 1.0 / t
        a[w + 2:, w + 1:n - 1] = np.eye(wf - 1)
    return a


def characteristic_polynomial(m: LoopModel, k6: float, k7: float, k_p: float,
                              true_scale: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Coefficients (highest power first) of a polynomial whose nonzero roots are the nonzero eigenvalues of
    :func:`transition`: the same loop in z, half the degree (roots of degree ~80 are 10-30 times cheaper than the
    eigenvalues of the ~160-state matrix).

    With ``DQ = (z - 1) Q / (T z)``, ``A = (z - 1)^2 Q / (T z)^2`` and ``CMD = C_q(z) Q + C_a(z) A`` (the FIR taps
    of the command on the q and a histories), the servo's ``(den z - 1) DQ = g CMD`` (``g = T kp / J``, ``den =
    1 + T D / J``) times ``T z^K`` is ``(den z - 1)(z - 1) z^(K-1) - g T z^K C_q - (g / T) z^(K-2) (z - 1)^2 C_a``.
    """
    w, t = m.window, m.period
    s0, d1, d2 = _taps(w, m.order, 0, t), _taps(w, m.order, 1, t), _taps(w, m.order, 2, t)
    cq = (m.k_v - k7) * d1 - m.k_tau * k_p * m.inertia * d2
    if m.encoder_position:
        cq[0] -= k6
    else:
        cq -= k6 * s0
    wf = m.ft_window if m.ft_inertia > 0 else 0
    ca = np.zeros(0)
    if wf:
        c_ft = 1.0 if m.contact else -k_p
        cq = cq - c_ft * m.k_tau * m.ft_inertia * d2
        ca = c_ft * m.k_tau * m.ft_inertia * _taps(wf, m.ft_order, 0, t)
    kt_true, kv_true = m.k_tau * true_scale[0], m.k_v * true_scale[1]
    g = t / (kt_true * m.inertia)
    den = 1.0 + t * (kv_true / kt_true) / m.inertia
    k = max(w - 1, wf + 1) + 1
    p = np.zeros(k + 2)  # p[d]: coefficient of z^d
    p[k + 1] += den
    p[k] -= den + 1.0
    p[k - 1] += 1.0
    p[k - np.arange(w)] -= g * t * cq
    if wf:
        i = np.arange(wf)
        p[k - i] -= (g / t) * ca
        p[k - i - 1] += (2.0 * g / t) * ca
        p[k - i - 2] -= (g / t) * ca
    return p[::-1]


def spectral_radius(a: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(a))))


@lru_cache(maxsize=4096)  # a pure function of frozen inputs: each controller built from a file asks again
def radius(m: LoopModel, k6: float, k7: float, k_p: float, true_scale: tuple[float, float] = (1.0, 1.0)) -> float:
    """Spectral radius of the closed loop (< 1: stable)."""
    return float(np.max(np.abs(np.roots(characteristic_polynomial(m, k6, k7, k_p, true_scale)))))


def dominant_mode(m: LoopModel, k6: float, k7: float, k_p: float,
                  true_scale: tuple[float, float] = (1.0, 1.0)) -> tuple[float, float]:
    """``(rho, frequency [Hz])`` of the closed loop's largest root: the oscillation that grows or decays
    slowest."""
    roots = np.roots(characteristic_polynomial(m, k6, k7, k_p, true_scale))
    e = roots[np.argmax(np.abs(roots))]
    return float(abs(e)), float(abs(np.angle(e)) / (2.0 * np.pi * m.period))


def worst_radius(m: LoopModel, k6: float, k7: float, k_p: float,
                 mismatch: Iterable[tuple[float, float]] = MISMATCH) -> float:
    """The largest spectral radius over servos that differ from the model by ``mismatch``."""
    return max(radius(m, k6, k7, k_p, s) for s in mismatch)
