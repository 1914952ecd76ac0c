"""``motor_lag``: first-order lag of the servo (current loop, filters).

``phi = lag(u, time_constant) - u``. On-line: ``tau``, ``dq`` and their history (a first-order lag).
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


def motor_lag(s: Signals, time_constant: float) -> np.ndarray:
    u = s["u"]
    return lowpass(u, time_constant, s.require_dt("motor_lag"), starts=s.starts) - u


class MotorLagOnline(OnlineLag):
    def __init__(self, shape: Mapping[str, float], period: float):
        super().__init__(shape["time_constant"], period, None)

    def value(self, x: Mapping[str, float]) -> float:
        return self._next(x["u"]) - x["u"]

    def commit(self, x: Mapping[str, float]) -> None:
        self.y = self._next(x["u"])


def needs(e: Excitation) -> str | None:
    """A time constant the sample period resolves, and fast motion."""
    return lag_resolved(e, GRID, "time constant") or fast_motion(e)


EFFECT = Effect(
    "motor_lag", motor_lag, GRID, ("t", "tau", "dq", "u"),
    signature="residual correlates with -du/dt: the servo reaches the expected error after a first-order lag",
    family="dynamics",
    description="first-order lag of the servo (current loop, filters)",
    needs=needs,
    online=MotorLagOnline,
    history=True,
    online_signals="tau, dq (history: a first-order lag)",
    confusable=("delay", "elastic"),
)
