"""``thermal_drift``: friction changing with the winding temperature (heated by the current).

``phi = h dq``, ``h = lag((u / U_REF)^2, tau_th)``: a heating proxy, the servo effort squared through a
first-order lag of ``tau_th`` [s]. On-line: ``tau``, ``dq`` and their history (a first-order lag of the servo
effort).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation
from ..registry import Effect
from ..signals import OnlineLag, Signals, lowpass

ORDER = 100
U_REF = 1e-3  # [rad] scale of u in the heating proxy
GRID = tuple({"tau_th": v} for v in (10.0, 30.0, 100.0))  # [s]
THERMAL_COEFFICIENT = (-math.inf, 0.0)
"""Heat lowers the lubricant's viscosity: the velocity slope falls as the winding heats (the coefficient is <= 0).
A positive coefficient (friction growing with the dissipated power) is a memory correction of high effort, not a
drift: fitted on simulated logs with a current limit and no drift, the slope would have grown by 45 to 200 %
(the simulated drift: -25 %)."""


def thermal_drift(s: Signals, tau_th: float) -> np.ndarray:
    dt = s.require_dt("thermal_drift")
    heat = lowpass((s["u"] / U_REF) ** 2, tau_th, dt, y0=0.0, starts=s.starts)
    return heat * s["dq"]


class ThermalOnline(OnlineLag):
    def __init__(self, shape: Mapping[str, float], period: float):
        super().__init__(shape["tau_th"], period, 0.0)

    def value(self, x: Mapping[str, float]) -> float:
        return self._next((x["u"] / U_REF) ** 2) * x["dq"]

    def commit(self, x: Mapping[str, float]) -> None:
        self.y = self._next((x["u"] / U_REF) ** 2)


def needs(e: Excitation) -> str | None:
    """A log long enough for the winding to heat."""
    if e.duration < 10.0:
        return f"duration {e.duration:.1f} s: expected >= 10 s for a thermal drift"
    return None


EFFECT = Effect(
    "thermal_drift", thermal_drift, GRID, ("t", "tau", "dq", "u"),
    signature="residual against time: the velocity slope of the residual drifts as the motor heats",
    family="time",
    description="friction changing with the winding temperature (heated by the current)",
    needs=needs,
    online=ThermalOnline,
    history=True,
    online_signals="tau, dq (history: a first-order lag of the servo effort)",
    coefficient_range=THERMAL_COEFFICIENT,
)
