"""``motor_lag``: first-order lag of the servo's torque (current loop, filters).

The motor torque lags the servo's command: ``T dtau/dt = K e - D dq - tau``, so the command the servo worked from
is ``tau + T dtau/dt``, not the measured ``tau``, and the error ``e = k_tau (tau + T dtau/dt) + k_v dq``. The
regressor is ``phi = lag(u_tau, time_constant) - u_tau`` (``u_tau = k_tau tau``), about
``-time_constant d(u_tau)/dt`` on slow motion, so its coefficient is about ``-T / time_constant``: negative for a
lag (``LAG_COEFFICIENT``; a positive one would be a lead, not this effect). Only the torque part lags: the
damping ``k_v dq`` acts on the measured velocity.

The lag form is a derivative only below ``1 / (2 pi time_constant)``; a stiff servo's torque moves faster. The
derivative form (``time_constant = 0``, the form's limit) is ``phi = (u_tau(t - 1 tick) - u_tau(t)) / period``,
about ``-d(u_tau)/dt`` at every frequency the log resolves: its coefficient is ``T`` [s] with a minus sign, the same
at any sample period (a controller running at another rate than the log applies it as fitted). On-line: ``tau``
and its history (a first-order lag, or the last tick's ``u_tau``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, ResolvedGrid, fast_motion, lag_resolved
from ..registry import Effect
from ..signals import OnlineLag, Signals, delayed, lowpass

ORDER = 130
SHAPES = tuple({"time_constant": v} for v in (0.0, 0.005, 0.01, 0.02, 0.05))  # [s] (0: the derivative form)
GRID = ResolvedGrid(SHAPES, ("time_constant",))  # the time constants the sample period resolves
LAG_COEFFICIENT = (float("-inf"), 0.0)  # -T / time_constant: a lag, never a lead


def motor_lag(s: Signals, time_constant: float) -> np.ndarray:
    u = s["u_tau"]
    if time_constant == 0.0:  # the derivative form reads the last tick: a uniform sampling
        return (delayed(u, 1, s.starts) - u) / s.require_dt("motor_lag")
    return lowpass(u, time_constant, s.require_dt("motor_lag"), starts=s.starts) - u


def time_constant_of(coefficient: float, shape: Mapping[str, float]) -> float:
    """The lag ``T`` [s] a fitted ``coefficient`` of ``shape`` gives: ``-coefficient`` times the shape's time
    constant, or ``-coefficient`` itself in the derivative form."""
    return -coefficient * (shape["time_constant"] or 1.0)


def shape_text(coefficient: float, shape: Mapping[str, float]) -> str:
    """The verdict's words for a fitted term: the time constant ``T`` its coefficient gives, and the form."""
    t_ms = 1e3 * time_constant_of(coefficient, shape)
    if shape["time_constant"] == 0.0:
        return f"derivative form: time constant {t_ms:.3g} ms"
    return f"lag form {1e3 * shape['time_constant']:.3g} ms: time constant {t_ms:.3g} ms"


class MotorLagOnline(OnlineLag):
    def __init__(self, shape: Mapping[str, float], period: float):
        super().__init__(shape["time_constant"], period, None)
        self.derivative = shape["time_constant"] == 0.0
        self.period = period

    def value(self, x: Mapping[str, float]) -> float:
        if self.derivative:
            return 0.0 if self.y is None else (self.y - x["u_tau"]) / self.period
        return self._next(x["u_tau"]) - x["u_tau"]

    def commit(self, x: Mapping[str, float]) -> None:
        self.y = x["u_tau"] if self.derivative else self._next(x["u_tau"])


def needs(e: Excitation) -> str | None:
    """A time constant the sample period resolves, and fast motion."""
    return lag_resolved(e, GRID, "time constant") or fast_motion(e)


EFFECT = Effect(
    "motor_lag", motor_lag, GRID, ("t", "tau", "u_tau"),
    signature="residual correlates with the torque's rate: the motor torque reaches the servo's command after a "
              "first-order lag",
    family="dynamics",
    description="first-order lag of the servo's torque (current loop, filters)",
    needs=needs,
    online=MotorLagOnline,
    history=True,
    online_signals="tau (history: a first-order lag)",
    coefficient_range=LAG_COEFFICIENT,
    shape_text=shape_text,
    confusable=("delay", "elastic"),
    phi_unit={"time_constant 0 (the derivative form: the coefficient is -T)": "rad/s", "time_constant > 0": "target"},
)
