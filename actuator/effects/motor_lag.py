"""``motor_lag``: first-order lag of the servo's torque (current loop, filters).

The motor torque lags the servo's command: ``T dtau/dt = K e - D dq - tau``, so the command the servo worked from
is ``tau + T dtau/dt``, not the measured ``tau``, and the error ``e = k_tau (tau + T dtau/dt) + k_v dq``. The
regressor is ``phi = lag(u_tau, time_constant) - u_tau`` (``u_tau = k_tau tau``), about
``-time_constant d(u_tau)/dt`` on slow motion, so its coefficient is about ``-T / time_constant``: negative for a
lag (``LAG_COEFFICIENT``; a positive one would be a lead, not this effect). Only the torque part lags: the
damping ``k_v dq`` acts on the measured velocity. On-line: ``tau`` and its history (a first-order lag).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, ResolvedGrid, fast_motion, lag_resolved
from ..registry import Effect
from ..signals import OnlineLag, Signals, lowpass

ORDER = 130
SHAPES = tuple({"time_constant": v} for v in (0.005, 0.01, 0.02, 0.05))  # [s]
GRID = ResolvedGrid(SHAPES, ("time_constant",))  # the time constants the sample period resolves
LAG_COEFFICIENT = (float("-inf"), 0.0)  # -T / time_constant: a lag, never a lead


def motor_lag(s: Signals, time_constant: float) -> np.ndarray:
    u = s["u_tau"]
    return lowpass(u, time_constant, s.require_dt("motor_lag"), starts=s.starts) - u


class MotorLagOnline(OnlineLag):
    def __init__(self, shape: Mapping[str, float], period: float):
        super().__init__(shape["time_constant"], period, None)

    def value(self, x: Mapping[str, float]) -> float:
        return self._next(x["u_tau"]) - x["u_tau"]

    def commit(self, x: Mapping[str, float]) -> None:
        self.y = self._next(x["u_tau"])


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
    confusable=("delay", "elastic"),
    phi_unit="target",
)
