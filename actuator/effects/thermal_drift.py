"""``thermal_drift``: the servo changing with the winding temperature (heated by the current).

``h = lag((u / U_REF)^2, tau_th)``: a heating proxy, the servo effort squared through a first-order lag of
``tau_th`` [s]. Two forms (shape ``gain``): ``phi = h dq`` (``gain = 0``): the friction's velocity slope changes
as the lubricant heats; ``phi = -h u_tau`` (``gain = 1``, ``u_tau = k_tau tau``): the torque per ampere falls as
the magnets heat, so the servo needs more command, hence more error, for the same torque (the damping acts on the
measured velocity and does not scale). Either way the coefficient is <= 0 (``THERMAL_COEFFICIENT``). On-line:
``tau``, ``dq`` and their history (a first-order lag of the servo effort).
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
GRID = tuple({"tau_th": v, "gain": g} for g in (0.0, 1.0) for v in (3.0, 10.0, 30.0, 100.0))  # [s], form
THERMAL_COEFFICIENT = (-math.inf, 0.0)
"""Heat lowers the lubricant's viscosity (the velocity slope falls) and the torque constant (more error for the
same torque, the column ``-h u_tau``): either way the coefficient is <= 0.
A positive coefficient (friction growing with the dissipated power) is a memory correction of high effort, not a
drift: fitted on simulated logs with a current limit and no drift, the slope would have grown by 45 to 200 %
(the simulated drift: -25 %)."""


def thermal_drift(s: Signals, tau_th: float, gain: float = 0.0) -> np.ndarray:
    dt = s.require_dt("thermal_drift")
    heat = lowpass((s["u"] / U_REF) ** 2, tau_th, dt, y0=0.0, starts=s.starts)
    return -heat * s["u_tau"] if gain else heat * s["dq"]


class ThermalOnline(OnlineLag):
    def __init__(self, shape: Mapping[str, float], period: float):
        super().__init__(shape["tau_th"], period, 0.0)
        self.gain = bool(shape.get("gain", 0.0))

    def value(self, x: Mapping[str, float]) -> float:
        return self._next((x["u"] / U_REF) ** 2) * (-x["u_tau"] if self.gain else x["dq"])

    def commit(self, x: Mapping[str, float]) -> None:
        self.y = self._next((x["u"] / U_REF) ** 2)


def needs(e: Excitation) -> str | None:
    """A log long enough for the winding to heat."""
    if e.duration < 10.0:
        return f"duration {e.duration:.1f} s: expected >= 10 s for a thermal drift"
    return None


EFFECT = Effect(
    "thermal_drift", thermal_drift, GRID, ("t", "tau", "dq", "u", "u_tau"),
    signature="residual against time: the velocity slope or the gain of the residual drifts as the motor heats",
    family="time",
    description="friction or torque constant changing with the winding temperature (heated by the current)",
    needs=needs,
    online=ThermalOnline,
    history=True,
    online_signals="tau, dq (history: a first-order lag of the servo effort)",
    coefficient_range=THERMAL_COEFFICIENT,
    phi_unit={"gain 0": "rad/s", "gain 1": "target"},
)
