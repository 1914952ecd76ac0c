"""The built-in library of physical effects (registered at import).

Each effect adds ``c * phi`` [rad] to ``dq_err = q_des - q``. Torques in the servo enter ``dq_err``
divided by the position gain, so a friction torque ``f`` appears as ``k_tau f``: the coefficients
below are in [rad] per unit of ``phi``. ``u = k_tau tau + k_v dq`` is the linear part of the model
the effect is added to. ``s(x, v) = tanh(x / v)`` is a sign smoothed over ``v`` (``v = 0``: plain sign).

========================  =====================================================  ==========================
effect                    phi                                                    on-line signals
========================  =====================================================  ==========================
``coulomb``               ``s(dq, v_eps)``                                       dq
``coulomb_asym``          ``|s(dq, v_eps)|``                                     dq
``stribeck``              ``s(dq, v_eps) exp(-(dq / v_s)^2)``                    dq
``stiction``              ``z exp(-(dq / v_th)^2)``, z = sign of the last move   dq history (a latch)
``deadzone``              ``c + (1 - |c|) z exp(-(dq / v_th)^2)``, see below    tau, dq (+ a latch if v_th;
                                                                                 q, q_des if crossing)
``direction_gain``        ``s(dq, v_eps) u``                                     tau, dq
``load_friction``         ``|tau| s(dq, v_eps)``                                 tau, dq
``backlash``              ``a (1 + gain exp(-(tau / tau_band)^2))``              tau, ddq (+ history if lag)
``cogging``               ``sin(2 pi q / period + phase)``                       q
``thermal_drift``         ``h dq``, ``h`` = lag(``(u / 1 mrad)^2``, tau_th)      tau, dq history (a lag)
``saturation``            ``[sat] (lead(t) - lead(t_onset))``, see below         tau, dq, q, q_des (history)
``elastic``               ``a``                                                  ddq (+ history if lag)
``motor_lag``             ``lag(u, time_constant) - u``                          tau, dq history (a lag)
``delay``                 ``q_des(t) - q_des(t - delay)``                        q_des history
========================  =====================================================  ==========================

``deadzone``: ``c = clip(m / band, -1, 1)`` with the servo effort ``m = u - damping_share u_v``, and
``z`` the sign of the last ``|m| > band`` (``v_th = 0``: no latch, ``phi = c``). A dead band on the position
error lets the joint rest anywhere inside it with no servo torque: held by friction after a push it stays
at the edge it was pushed to (``z``); crossing the band freely (fast) it is on average at the centre.
Crossing form (``crossing = 1``, offered when the log has ``q`` and ``q_des``): ``sign(m)`` outside the band;
inside, ``z + (lead(t) - lead(t_entry)) / width``: the joint is free there and its error follows the command's
lead (``q_des(t - 1) - q(t)``, as for ``saturation``) from the edge it entered at. It is fitted as two columns,
the edge and the lead since the entry; ``width`` [rad], the band's half-width, is the ratio of their coefficients
(the lead's is 1 in theory). Simulated knee, 3 mrad dead band: width 3.4 mrad, fall 0.95 (docs/workbench.md).

``saturation``: saturated while the motor-torque proxy ``|tau + beta dq|`` exceeds ``tau_sat`` [N m] (until it
falls below ``release tau_sat``); ``lead = q_des(t - 1 tick) - q(t)``, its change since the onset of the limit is
the integral of the command's lead the servo cannot close (the measured error since the onset: the term resets
the model to the error measured when the limit was reached). ``beta`` [N m s/rad] is the damping outside the
servo; the proxy reads the signals, not ``u`` (a fit on saturated data bends the model). Simulated knee, 2.5 A
limit, fast excitation: held-out gain 0.97, fall 0.98, coefficient 1.0 (docs/workbench.md); coefficients
outside ``SATURATION_COEFFICIENT`` are not chosen.

``a`` is the acceleration ``ddq`` (centred SG of ``q`` over ``window``, or the estimator's), delayed by
``lag`` like the torque estimate (see :func:`inertia`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from .effects import Effect, register_effect
from .excitation import Excitation
from .signals import (
    Signals,
    delayed,
    direction_latch,
    hysteresis,
    lowpass,
    lowpass_gain,
    sign_latch,
    since_onset,
    ticks,
)

U_REF = 1e-3  # [rad] scale of u in the thermal heating proxy


def smooth_sign(x: np.ndarray, v: float) -> np.ndarray:
    """``tanh(x / v)``, or ``sign(x)`` for ``v <= 0``."""
    return np.sign(x) if v <= 0.0 else np.tanh(x / v)


# -- excitation requirements: a reason string when the data cannot test the effect ---------------------
def _both_directions(e: Excitation) -> str | None:
    if e.velocity_reversals < 2:
        return f"only {e.velocity_reversals} velocity reversals: expected motion in both directions (>= 2)"
    return None


def _slow_and_fast(e: Excitation) -> str | None:
    if e.slow_time < 0.5 or e.fast_time < 0.5:
        return (f"slow motion {e.slow_time:.1f} s, fast motion {e.fast_time:.1f} s: expected >= 0.5 s of each "
                "(the Stribeck curve needs several speeds)")
    return _both_directions(e)


def _holds_after_motion(e: Excitation) -> str | None:
    if e.hold_time < 0.5:
        return f"hold time {e.hold_time:.1f} s: expected >= 0.5 s of holding still after motion"
    return _both_directions(e)


def _torque_reversal_at_rest(e: Excitation) -> str | None:
    if e.torque_range is None:
        return "no torque column"
    if e.torque_reversals_at_rest < 1:
        return ("the torque never changed sign while holding still: a dead zone looks like Coulomb friction; "
                "push the joint through zero torque at rest")
    return None


def _torque_reversal(e: Excitation) -> str | None:
    if e.torque_range is None:
        return "no torque column"
    if e.torque_reversals < 2:
        return f"{e.torque_reversals} torque sign changes: expected >= 2 (the gear must cross its play)"
    return None


def _loaded_motion(e: Excitation) -> str | None:
    if e.torque_range is None:
        return "no torque column"
    if e.loaded_motion < 0.05:
        return f"loaded motion {100 * e.loaded_motion:.0f} %: expected >= 5 % of moving samples under high torque"
    return _both_directions(e)


def _position_sweep(e: Excitation) -> str | None:
    if e.position_range is None:
        return "no position column"
    if e.position_range[1] - e.position_range[0] < 0.05:
        return "position range < 0.05 rad: expected a sweep over several ripple periods"
    return None


def _long_enough(e: Excitation) -> str | None:
    if e.duration < 10.0:
        return f"duration {e.duration:.1f} s: expected >= 10 s for a thermal drift"
    return None


def _fast(e: Excitation) -> str | None:
    if e.fast_time < 0.5:
        return f"fast motion {e.fast_time:.1f} s: expected >= 0.5 s faster than 0.3 rad/s (dynamics)"
    return None


def _has_torque(e: Excitation) -> str | None:
    return "no torque column" if e.torque_range is None else None


# -- regressors ---------------------------------------------------------------------------------------
def coulomb(s: Signals, v_eps: float) -> np.ndarray:
    return smooth_sign(s["dq"], v_eps)


def coulomb_asym(s: Signals, v_eps: float) -> np.ndarray:
    return np.abs(smooth_sign(s["dq"], v_eps))


def stribeck(s: Signals, v_s: float, v_eps: float) -> np.ndarray:
    dq = s["dq"]
    return smooth_sign(dq, v_eps) * np.exp(-((dq / v_s) ** 2))


def stiction(s: Signals, v_th: float) -> np.ndarray:
    dq = s["dq"]
    return direction_latch(dq, v_th) * np.exp(-((dq / v_th) ** 2))


def deadzone(
    s: Signals, band: float, damping_share: float = 0.0, v_th: float = 0.0, crossing: float = 0.0, width: float = 0.0
) -> np.ndarray:
    """A step of the error at zero servo effort ``m = u - damping_share u_v`` [rad], smoothed over ``band``
    [rad]; with ``v_th > 0`` [rad/s], where the effort is inside the band the joint rests at the edge of the
    dead band it was last pushed against (the sign of the last ``|m| > band``), fading to the band's centre
    as it moves faster than ``v_th`` (crossing the band freely).

    ``crossing = 1``: the crossing form of a dead band on the position error (``v_th`` unused). Outside it
    the step ``sign(m)``; inside, the joint is free and its error follows the command's lead from the edge it
    entered at: ``z + (lead(t) - lead(t_entry)) / width``, ``z`` the sign of the last effort outside,
    ``lead = q_des(t - 1) - q(t)`` (:func:`command_lead`), ``width`` [rad] the band's half-width (0: the edge
    alone). The joint enters the band when ``|m| <= band`` and leaves it when ``|m| > DZ_RELEASE band``
    (hysteresis). Reads ``q`` and ``q_des``: the target must be ``q_des - q``.
    """
    if crossing:
        edge, lead = _deadzone_crossing(s, band, damping_share)
        return edge + lead / width if width else edge
    m = s["u"] - damping_share * s["u_v"]
    step = np.clip(m / band, -1.0, 1.0)
    if v_th <= 0.0:
        return step
    rest = direction_latch(m, band) * np.exp(-((s["dq"] / v_th) ** 2))
    return step + (1.0 - np.abs(step)) * rest


def _deadzone_crossing(s: Signals, band: float, damping_share: float) -> tuple[np.ndarray, np.ndarray]:
    """The two columns of the crossing form: the edge (``sign(m)`` outside the band, inside the sign of the
    last effort outside) and the command's lead since the entry into the band [rad] (0 outside)."""
    m = s["u"] - damping_share * s["u_v"]
    outside = hysteresis(np.abs(m), DZ_RELEASE * band, band)
    inside = ~outside
    edge = np.where(inside, sign_latch(m, outside), np.sign(m))
    return edge, since_onset(command_lead(s), inside)


def _deadzone_columns(
    s: Signals, band: float, damping_share: float = 0.0, v_th: float = 0.0, crossing: float = 0.0, width: float = 0.0
) -> np.ndarray:
    """The step alone, or (crossing form) the edge and the lead since the entry, fitted separately: their
    coefficients are the band's half-width and the part of the lead the error keeps (1 in theory)."""
    if not crossing:
        return deadzone(s, band, damping_share, v_th)
    return np.column_stack(_deadzone_crossing(s, band, damping_share))


def _deadzone_fold(c: np.ndarray, shape: Mapping[str, float]) -> tuple[float, dict[str, float]]:
    # c_edge edge + c_lead lead = c_edge (edge + lead / width), width = c_edge / c_lead
    if not shape.get("crossing"):
        return float(c[0]), dict(shape)
    return float(c[0]), {**shape, "width": float(c[0] / c[1]) if c[1] != 0.0 else 0.0}


def _deadzone_grid(s: Signals) -> tuple[dict[str, float], ...]:
    """The step (with or without the rest latch) for every band and damping share; with the command and the
    position in the log, the crossing form too, for a dead band on the position error (shares 0 and 0.33:
    inside such a band the servo's damping still acts, so the effort is ``u`` or close to it)."""
    out = [{"band": b, "damping_share": d, "v_th": v} for d in _DZ_SHARES for b in _DZ_BANDS for v in _REST]
    if "q" in s and "q_des" in s:
        out += [{"band": b, "damping_share": d, "crossing": 1.0} for d in _DZ_SHARES[:2] for b in _DZ_BANDS]
    return tuple(out)


def deadzone_signals(shape: Mapping[str, float]) -> tuple[str, ...]:
    """Signals the ``deadzone`` term of ``shape`` reads besides its own: ``q`` and ``q_des`` in the crossing form."""
    return ("q", "q_des") if shape.get("crossing") else ()


def direction_gain(s: Signals, v_eps: float) -> np.ndarray:
    return smooth_sign(s["dq"], v_eps) * s["u"]


def load_friction(s: Signals, v_eps: float) -> np.ndarray:
    return np.abs(s["tau"]) * smooth_sign(s["dq"], v_eps)


def acceleration(s: Signals, window: float) -> np.ndarray:
    """The acceleration [rad/s^2]: an estimate given with the data (``ddq_est``: an acceleration column of
    the log, or the controller's estimator on-line), else the centred SG second derivative of ``q`` over
    ``window`` [s] (order 3)."""
    from servotau.estimation.savgol import savgol_centred

    if "ddq_est" in s:
        return s["ddq_est"]
    if window <= 0.0:
        return s["ddq"]
    dt = s.require_dt("acceleration")
    w = max(5, int(round(window / dt)) | 1)
    if w > s.n:
        return s["ddq"]
    return s.derived("q", ("ddq", w, dt), lambda q: savgol_centred(q, w, 3, dt, deriv=2))


def inertia(s: Signals, window: float, lag: float = 0.0) -> np.ndarray:
    """The acceleration of :func:`acceleration`, delayed by ``lag`` [s] like the torque estimate.

    The servo torque is the link torque plus the rotor's inertia torque ``J ddq``; when the torque column
    is an estimate that lags the encoders (an estimator's delay), only an equally delayed inertia term
    completes it into the (smooth) servo torque of that earlier instant. ``lag = 0``: no delay.
    """
    a = acceleration(s, window)
    if lag <= 0.0:
        return a
    return delayed(a, ticks(lag, s.require_dt("the lag of the inertia term")))


def backlash(s: Signals, window: float, tau_band: float, gain: float, lag: float = 0.0) -> np.ndarray:
    return inertia(s, window, lag) * (1.0 + gain * np.exp(-((s["tau"] / tau_band) ** 2)))


def cogging(s: Signals, period: float, phase: float = 0.0) -> np.ndarray:
    return np.sin(2.0 * math.pi * s["q"] / period + phase)


def _cogging_columns(s: Signals, period: float) -> np.ndarray:
    x = 2.0 * math.pi * s["q"] / period
    return np.column_stack([np.sin(x), np.cos(x)])


def _cogging_fold(c: np.ndarray, shape: Mapping[str, float]) -> tuple[float, dict[str, float]]:
    # a sin(x) + b cos(x) = r sin(x + phase)
    return float(math.hypot(c[0], c[1])), {**shape, "phase": float(math.atan2(c[1], c[0]))}


THERMAL_COEFFICIENT = (-math.inf, 0.0)
"""Heat lowers the lubricant's viscosity: the velocity slope falls as the winding heats (the coefficient is <= 0).
A positive coefficient (friction growing with the dissipated power) is a memory correction of high effort, not a
drift: fitted on simulated logs with a current limit and no drift, the slope would have grown by 45 to 200 %
(the simulated drift: -25 %)."""


def thermal_drift(s: Signals, tau_th: float) -> np.ndarray:
    dt = s.require_dt("thermal_drift")
    heat = lowpass((s["u"] / U_REF) ** 2, tau_th, dt, y0=0.0)
    return heat * s["dq"]


def motor_torque_proxy(s: Signals, beta: float) -> np.ndarray:
    """``tau + beta dq`` [N m]: the torque estimate plus the damping outside the servo (``beta`` [N m s/rad]),
    what the motor must produce; it sits at the current limit while the servo saturates. Read from the
    signals only, not from the model: a model fitted on saturated data is bent by them."""
    return s["tau"] + beta * s["dq"]


def command_lead(s: Signals) -> np.ndarray:
    """``q_des(t - 1 tick) - q(t)`` [rad]: the error the servo has to close at the start of the tick, up to
    the previous command (the integral of ``dq_des - dq``; this tick's command is not read)."""
    return delayed(s["q_des"], 1) - s["q"]


def saturation(s: Signals, tau_sat: float, beta: float, release: float = 0.8) -> np.ndarray:
    """The error's growth since the current limit was reached [rad], zero below the limit.

    Saturated: ``|tau + beta dq| > tau_sat`` [N m], held until it falls to ``release tau_sat`` (hysteresis:
    the proxy is noisy at the limit). Past the limit the servo torque no longer follows the error: the
    command's lead that the servo cannot close integrates, ``phi = lead(t) - lead(t_onset)`` with
    ``lead = q_des(t - 1) - q(t)`` (:func:`command_lead`). This is the measured error since the onset: the
    term resets the model to the error it measured when the limit was reached (output-error form).
    """
    flag = hysteresis(np.abs(motor_torque_proxy(s, beta)), tau_sat, release * tau_sat)
    return since_onset(command_lead(s), flag)


_SAT_LEVELS = (0.7, 0.8, 0.9, 0.95, 0.97, 0.99)  # quantiles of the proxy: the limit may hold up to 30 % of a log
_SAT_DAMPING = (0.5, 1.0, 1.5, 2.0)  # beta in units of the data's P99 |tau| / P99 |dq|
_SAT_RELEASE = 0.8  # leave the limit when the proxy falls below 80 % of it
SATURATION_COEFFICIENT = (0.5, 1.5)
"""The part of the command's lead the error keeps past the limit: 1 in theory, with the same margin of 0.5 on
both sides for a bent fit. Below half, the servo still closes most of the lead where the detector fires: it is
not at a limit (fitted 0.13 on a simulated log with Stribeck friction and thermal drift, no limit); outside
the range the term is a generic memory correction (fitted -1.5 and -2.0 on simulated logs without a limit)."""


def _saturation_grid(s: Signals) -> tuple[dict[str, float], ...]:
    """Thresholds at high quantiles of the motor-torque proxy ``|tau + beta dq|`` [N m] (the limit is where it
    piles up), for damping ``beta`` [N m s/rad] scaled by the data (its 99th percentiles of torque and
    velocity)."""
    dq99 = float(np.quantile(np.abs(s["dq"]), 0.99))
    scale = float(np.quantile(np.abs(s["tau"]), 0.99)) / dq99 if dq99 > 0 else 0.0
    out = []
    for f in _SAT_DAMPING if scale > 0 else (0.0,):
        beta = float(f"{f * scale:.3g}")
        levels = np.quantile(np.abs(motor_torque_proxy(s, beta)), _SAT_LEVELS)
        out += [{"tau_sat": float(f"{v:.4g}"), "beta": beta, "release": _SAT_RELEASE} for v in levels]
    return tuple(out)


def elastic(s: Signals, window: float, lag: float = 0.0) -> np.ndarray:
    return inertia(s, window, lag)


def motor_lag(s: Signals, time_constant: float) -> np.ndarray:
    u = s["u"]
    return lowpass(u, time_constant, s.require_dt("motor_lag")) - u


def delay(s: Signals, delay: float) -> np.ndarray:
    q_des = s["q_des"]
    return q_des - delayed(q_des, ticks(delay, s.require_dt("delay")))


# -- on-line evaluators of the effects with memory -----------------------------------------------------
class _StictionOnline:
    def __init__(self, shape: Mapping[str, float], period: float):
        self.v_th = shape["v_th"]
        self.z = 0.0

    def _z(self, dq: float) -> float:
        return math.copysign(1.0, dq) if abs(dq) > self.v_th else self.z

    def value(self, x: Mapping[str, float]) -> float:
        return self._z(x["dq"]) * math.exp(-((x["dq"] / self.v_th) ** 2))

    def commit(self, x: Mapping[str, float]) -> None:
        self.z = self._z(x["dq"])


def _lead(x: Mapping[str, float], q_des_prev: float | None) -> float:
    """:func:`command_lead` of one sample: the last tick's command (this tick's on the first) minus ``q``."""
    return (x["q_des"] if q_des_prev is None else q_des_prev) - x["q"]


class _DeadzoneOnline:
    """``deadzone`` on-line: the step, the latch of the sign of the last effort beyond the band and, in the
    crossing form, the last command and the lead at the entry into the band."""

    def __init__(self, shape: Mapping[str, float], period: float):
        self.band, self.share, self.v_th = shape["band"], shape.get("damping_share", 0.0), shape.get("v_th", 0.0)
        self.crossing, self.width = bool(shape.get("crossing", 0.0)), shape.get("width", 0.0)
        self.z = 0.0
        self.outside = False  # the detector's state (crossing form: with hysteresis)
        self.inside = False  # the last committed sample was inside the band (False before the first)
        self.q_des_prev: float | None = None  # [rad] the command of the last tick
        self.entry_lead = 0.0  # [rad]

    def _m(self, x: Mapping[str, float]) -> float:
        return x["u"] - self.share * x["u_v"]

    def _outside(self, m: float) -> bool:
        if not self.crossing:
            return abs(m) > self.band
        return abs(m) > (self.band if self.outside else DZ_RELEASE * self.band)  # hysteresis

    def value(self, x: Mapping[str, float]) -> float:
        m = self._m(x)
        outside = self._outside(m)
        if self.crossing:
            if outside:
                return math.copysign(1.0, m)
            if not self.inside or not self.width:  # entering the band at this tick, or the edge alone
                return self.z
            return self.z + (_lead(x, self.q_des_prev) - self.entry_lead) / self.width
        step = min(1.0, max(-1.0, m / self.band))
        if self.v_th <= 0.0:
            return step
        z = math.copysign(1.0, m) if outside else self.z
        return step + (1.0 - abs(step)) * z * math.exp(-((x["dq"] / self.v_th) ** 2))

    def commit(self, x: Mapping[str, float]) -> None:
        m = self._m(x)
        self.outside = self._outside(m)
        if self.outside:
            self.z = math.copysign(1.0, m)
        elif self.crossing and not self.inside:
            self.entry_lead = _lead(x, self.q_des_prev)
        self.inside = not self.outside
        if self.crossing:
            self.q_des_prev = x["q_des"]


class _LagOnline:
    """``y += a (x - y)`` on a signal of the sample; subclasses say what x is and what is returned."""

    def __init__(self, time_constant: float, period: float, y0: float | None):
        self.a = lowpass_gain(time_constant, period)
        self.y = y0

    def _next(self, x: float) -> float:
        y = x if self.y is None else self.y  # first sample: y[-1] = x[0] unless y0 was given
        return y + self.a * (x - y)


class _ThermalOnline(_LagOnline):
    def __init__(self, shape: Mapping[str, float], period: float):
        super().__init__(shape["tau_th"], period, 0.0)

    def value(self, x: Mapping[str, float]) -> float:
        return self._next((x["u"] / U_REF) ** 2) * x["dq"]

    def commit(self, x: Mapping[str, float]) -> None:
        self.y = self._next((x["u"] / U_REF) ** 2)


class _MotorLagOnline(_LagOnline):
    def __init__(self, shape: Mapping[str, float], period: float):
        super().__init__(shape["time_constant"], period, None)

    def value(self, x: Mapping[str, float]) -> float:
        return self._next(x["u"]) - x["u"]

    def commit(self, x: Mapping[str, float]) -> None:
        self.y = self._next(x["u"])


class _InertiaOnline:
    """``elastic`` and ``backlash`` on-line: the estimator's acceleration, delayed by ``lag`` (a buffer)."""

    def __init__(self, shape: Mapping[str, float], period: float):
        lag = shape.get("lag", 0.0)
        self.n = ticks(lag, period) if lag > 0.0 else 0
        self.tau_band, self.gain = shape.get("tau_band"), shape.get("gain", 0.0)
        self.buf: list[float] = []

    def _acc(self, x: Mapping[str, float]) -> float:
        a = _sample_acc(x)
        if self.n == 0:
            return a
        if len(self.buf) < self.n:
            return self.buf[0] if self.buf else a
        return self.buf[-self.n]

    def value(self, x: Mapping[str, float]) -> float:
        a = self._acc(x)
        if self.tau_band is None:
            return a
        return a * (1.0 + self.gain * math.exp(-((x["tau"] / self.tau_band) ** 2)))

    def commit(self, x: Mapping[str, float]) -> None:
        if self.n:
            self.buf.append(_sample_acc(x))
            if len(self.buf) > self.n:
                del self.buf[0]


class _DelayOnline:
    def __init__(self, shape: Mapping[str, float], period: float):
        self.n = ticks(shape["delay"], period)
        self.buf: list[float] = []

    def _old(self, q_des: float) -> float:
        if len(self.buf) < self.n:
            return self.buf[0] if self.buf else q_des
        return self.buf[-self.n]

    def value(self, x: Mapping[str, float]) -> float:
        return x["q_des"] - self._old(x["q_des"])

    def commit(self, x: Mapping[str, float]) -> None:
        self.buf.append(x["q_des"])
        if len(self.buf) > self.n:
            del self.buf[0]


class _SaturationOnline:
    """``saturation`` on-line: the limit detector's state, the last command and the lead at the onset."""

    def __init__(self, shape: Mapping[str, float], period: float):
        self.tau_sat, self.beta = shape["tau_sat"], shape["beta"]
        self.release = shape.get("release", _SAT_RELEASE)
        self.saturated = False
        self.q_des_prev: float | None = None  # [rad] the command of the last tick
        self.onset_lead = 0.0  # [rad]

    def _saturated(self, x: Mapping[str, float]) -> bool:
        level = self.release * self.tau_sat if self.saturated else self.tau_sat
        return abs(x["tau"] + self.beta * x["dq"]) > level

    def value(self, x: Mapping[str, float]) -> float:
        if not (self.saturated and self._saturated(x)):
            return 0.0  # below the limit, or its onset (this tick's command is not read)
        return _lead(x, self.q_des_prev) - self.onset_lead

    def commit(self, x: Mapping[str, float]) -> None:
        sat = self._saturated(x)
        if sat and not self.saturated:
            self.onset_lead = _lead(x, self.q_des_prev)
        self.saturated = sat
        self.q_des_prev = x["q_des"]


_V_EPS = (0.0, 0.005, 0.01, 0.02, 0.05)  # [rad/s] sign smoothing
_V_S = (0.01, 0.02, 0.04, 0.08, 0.16, 0.32)  # [rad/s] Stribeck velocities
_REST = (0.0, 0.01, 0.05)  # [rad/s] dead zone: resting below this speed at the last edge (0: no latch)
_DZ_BANDS = (3e-5, 1e-4, 3e-4, 1e-3)  # [rad] dead zone: the effort's smoothing band (the detector of the crossing form)
_DZ_SHARES = (0.0, 0.33, 0.67)  # dead zone: the part of k_v that is the servo's damping (0: a dead band on the error)
DZ_RELEASE = 1.5
"""Crossing form of ``deadzone``: the joint leaves the band when ``|m|`` exceeds ``DZ_RELEASE band`` and enters it
when ``|m|`` falls to ``band`` (hysteresis: the effort hovers at the band's edge during a slow crossing, and each
flicker would restart it from an edge). Tried 1 (none), 1.5 and 2 on the dead-zone log and its pair with cogging:
falls 0.957 / 0.894 (cogging not kept), 0.953 / 0.952, 0.949 / 0.944."""
_LAGS = (0.0, 0.002, 0.005)  # [s] delay of the inertia term (that of the torque estimate)

BUILTIN = (
    Effect(
        "coulomb", coulomb, tuple({"v_eps": v} for v in _V_EPS), ("dq",),
        "residual against velocity: a step at dq = 0, equal and opposite on both sides, flat beyond",
        "velocity", "Coulomb friction: a constant torque opposing the motion", _both_directions,
        confusable=("deadzone", "stribeck"),
    ),
    Effect(
        "coulomb_asym", coulomb_asym, tuple({"v_eps": v} for v in _V_EPS), ("dq",),
        "residual against velocity: the same offset on both sides of dq = 0 while moving, none at rest",
        "velocity", "Coulomb friction larger in one direction than in the other", _both_directions,
    ),
    Effect(
        "stribeck", stribeck, tuple({"v_s": v, "v_eps": e} for v in _V_S for e in (0.005, 0.01, 0.02)), ("dq",),
        "residual against velocity: opposite peaks just above and below dq = 0, fading beyond v_s",
        "velocity", "breakaway friction above Coulomb at low speed, decaying with speed", _slow_and_fast,
        confusable=("stiction", "coulomb"),
    ),
    Effect(
        "stiction", stiction, tuple({"v_th": v} for v in (0.005, 0.01, 0.02, 0.05)), ("dq",),
        "residual while holding still keeps the sign of the last motion",
        "velocity", "static friction holding the joint after a move, in the direction of that move",
        _holds_after_motion, online=_StictionOnline, history=True, confusable=("stribeck", "backlash"),
    ),
    Effect(
        "deadzone", deadzone, _deadzone_grid, ("tau", "dq", "u", "u_v"),
        "residual against the linear prediction u: a step at u = 0 (the servo needs a minimum error); at rest with "
        "no effort, the sign of the last effort (the joint stays at the edge of the dead band it was pushed to); "
        "while the effort is near zero, the error follows the command's lead (the joint crosses the band freely)",
        "servo_error", "dead zone of the servo (on the position error or the current)", _torque_reversal_at_rest,
        fit_columns=_deadzone_columns, fold=_deadzone_fold, online=_DeadzoneOnline,
        confusable=("backlash", "coulomb"), shape_signals=deadzone_signals,
    ),
    Effect(
        "direction_gain", direction_gain, tuple({"v_eps": v} for v in _V_EPS[1:]), ("tau", "dq", "u"),
        "residual proportional to u with opposite slopes for dq > 0 and dq < 0",
        "servo_error", "servo gain that changes with the direction of motion", _both_directions,
        confusable=("load_friction",),
    ),
    Effect(
        "load_friction", load_friction, tuple({"v_eps": v} for v in _V_EPS[1:]), ("tau", "dq"),
        "residual against torque split by velocity sign: a V (|tau|) with opposite signs for dq > 0 and dq < 0",
        "torque", "friction growing with the transmitted load", _loaded_motion, confusable=("direction_gain",),
    ),
    Effect(
        "backlash", backlash,
        tuple({"window": w, "tau_band": b, "gain": g, "lag": lag}
              for w in (0.011, 0.021) for b in (2.0, 5.0, 10.0) for g in (1.0, 3.0) for lag in _LAGS),
        ("q", "tau"),
        "residual follows the motor acceleration, more strongly while the torque is near zero (the rotor crosses "
        "the play unloaded)",
        "dynamics", "compliant gear with play: the rotor inertia acts behind the gear, freely inside the play",
        _torque_reversal, online=_InertiaOnline,
        confusable=("elastic", "deadzone"),
    ),
    Effect(
        "cogging", cogging, tuple({"period": p} for p in np.geomspace(0.01, 0.32, 11).round(4).tolist()), ("q",),
        "residual against position: a ripple of fixed period",
        "position", "torque ripple periodic in the joint angle (motor cogging, gear tooth mesh)", _position_sweep,
        fit_columns=_cogging_columns, fold=_cogging_fold,
    ),
    Effect(
        "thermal_drift", thermal_drift, tuple({"tau_th": v} for v in (10.0, 30.0, 100.0)), ("t", "tau", "dq", "u"),
        "residual against time: the velocity slope of the residual drifts as the motor heats",
        "time", "friction changing with the winding temperature (heated by the current)", _long_enough,
        online=_ThermalOnline, history=True, coefficient_range=THERMAL_COEFFICIENT,
    ),
    Effect(
        "saturation", saturation, _saturation_grid, ("q", "q_des", "tau", "dq"),
        "large residuals of one sign where the motor-torque proxy |tau + beta dq| sits at its largest values (the "
        "current limit), growing with the command's lead over the joint while it stays there",
        "servo_error", "current limit: past it the servo torque no longer follows the position error, which "
        "integrates the command's lead the servo cannot close", _has_torque, online=_SaturationOnline, history=True,
        coefficient_range=SATURATION_COEFFICIENT,
    ),
    Effect(
        "elastic", elastic, tuple({"window": w, "lag": lag} for w in (0.011, 0.021, 0.041, 0.081) for lag in _LAGS),
        ("q",),
        "residual proportional to the acceleration (rotor inertia behind a compliant gear)",
        "dynamics", "elastic gear: the motor inertia acts behind the spring, outside the link torque", _fast,
        online=_InertiaOnline, confusable=("backlash", "motor_lag", "delay"),
    ),
    Effect(
        "motor_lag", motor_lag, tuple({"time_constant": v} for v in (0.005, 0.01, 0.02, 0.05)),
        ("t", "tau", "dq", "u"),
        "residual correlates with -du/dt: the servo reaches the expected error after a first-order lag",
        "dynamics", "first-order lag of the servo (current loop, filters)", _fast, online=_MotorLagOnline,
        history=True, confusable=("delay", "elastic"),
    ),
    Effect(
        "delay", delay, tuple({"delay": v} for v in (0.002, 0.005, 0.01, 0.02)), ("t", "q_des"),
        "residual correlates with the command velocity: the servo sees q_des late",
        "dynamics", "dead time between the command and the servo", _fast, online=_DelayOnline, history=True,
        confusable=("motor_lag", "elastic"),
    ),
)

for _effect in BUILTIN:
    register_effect(_effect, replace=True)

EXPERIMENTS = {
    frozenset(("direction_gain", "load_friction")): (
        "move in both directions under torques of both signs (push the limb while it moves): a direction gain "
        "follows the sign of u, load friction the magnitude |tau|"
    ),
    frozenset(("deadzone", "backlash")): (
        "reverse the torque at rest (a push through zero), then move fast against a constant load: a dead zone "
        "follows the sign of the servo error u, backlash the sign of the torque"
    ),
    frozenset(("deadzone", "coulomb")): (
        "hold still and push the joint through zero torque: Coulomb friction vanishes at rest, a dead zone does not"
    ),
    frozenset(("stribeck", "stiction")): (
        "constant-velocity ramps at several slow speeds (0.01 to 0.3 rad/s) and holds approached from both "
        "sides: Stribeck friction decays with speed, stiction acts only at rest with the sign of the last move"
    ),
    frozenset(("stribeck", "coulomb")): (
        "constant-velocity ramps at several speeds: the Stribeck excess fades with speed, Coulomb friction stays"
    ),
    frozenset(("delay", "motor_lag")): (
        "command steps or a chirp: a dead time shows a flat start and a phase lag growing linearly with "
        "frequency; a first-order lag responds at once and its phase saturates at 90 degrees"
    ),
    frozenset(("elastic", "backlash")): (
        "reverse the torque slowly at rest and compare a link-side angle with the motor encoder: backlash jumps by "
        "the play at zero torque, an elastic gear deflects in proportion to the torque (model the deflection "
        "q_motor - q_link against the torque: play shows as a 'deadzone' step of half the play)"
    ),
    frozenset(("elastic", "motor_lag")): (
        "a chirp of the command at constant load: the acceleration term grows with the square of the frequency, "
        "a lag's phase saturates"
    ),
    frozenset(("elastic", "delay")): (
        "command steps (or a chirp): a dead time shows a flat start, the rotor inertia a response to the "
        "acceleration from the first sample"
    ),
    frozenset(("stiction", "backlash")): (
        "hold after moving in each direction under the same load, then reverse the load at rest: stiction keeps "
        "the sign of the last move, backlash follows the sign of the torque"
    ),
}


# -- scalar versions of the effects without memory, for the on-line evaluator (one sample at a time) ----
def _ssign(x: float, v: float) -> float:
    return (x > 0) - (x < 0) if v <= 0.0 else math.tanh(x / v)


def _sample_acc(x: Mapping[str, float]) -> float:
    return x["ddq_est"] if "ddq_est" in x else x["ddq"]


SCALAR = {
    "coulomb": lambda x, v_eps: _ssign(x["dq"], v_eps),
    "coulomb_asym": lambda x, v_eps: abs(_ssign(x["dq"], v_eps)),
    "stribeck": lambda x, v_s, v_eps: _ssign(x["dq"], v_eps) * math.exp(-((x["dq"] / v_s) ** 2)),
    "direction_gain": lambda x, v_eps: _ssign(x["dq"], v_eps) * x["u"],
    "load_friction": lambda x, v_eps: abs(x["tau"]) * _ssign(x["dq"], v_eps),
    "cogging": lambda x, period, phase=0.0: math.sin(2.0 * math.pi * x["q"] / period + phase),
}
"""``phi(sample, **shape)`` of the built-in effects without memory, on one sample (a mapping of floats)."""
