"""``stiction``: static friction holding the joint after a move, in the direction of that move.

``phi = z exp(-(dq / v_th)^2)``, ``z`` the sign of the last velocity beyond ``v_th`` [rad/s] (a latch). On-line:
``dq`` and its history (the latch).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, both_directions, held
from ..registry import Effect
from ..signals import Signals, bell_of, direction_latch

ORDER = 40
GRID = tuple({"v_th": v} for v in (0.005, 0.01, 0.02, 0.05))


def stiction(s: Signals, v_th: float) -> np.ndarray:
    dq = s["dq"]
    return direction_latch(dq, v_th, s.starts) * bell_of(s, "dq", v_th)


class StictionOnline:
    """On-line ``stiction``: the latch of the last direction."""

    def __init__(self, shape: Mapping[str, float], period: float):
        self.v_th = shape["v_th"]
        self.z = 0.0

    def _z(self, dq: float) -> float:
        return math.copysign(1.0, dq) if abs(dq) > self.v_th else self.z

    def value(self, x: Mapping[str, float]) -> float:
        return self._z(x["dq"]) * math.exp(-((x["dq"] / self.v_th) ** 2))

    def commit(self, x: Mapping[str, float]) -> None:
        self.z = self._z(x["dq"])


def needs(e: Excitation) -> str | None:
    """Holds after motion, in both directions."""
    return held(e) or both_directions(e)


EFFECT = Effect(
    "stiction", stiction, GRID, ("dq",),
    signature="residual while holding still keeps the sign of the last motion",
    family="velocity",
    description="static friction holding the joint after a move, in the direction of that move",
    needs=needs,
    online=StictionOnline,
    history=True,
    online_signals="dq (history: a latch of the last direction)",
    confusable=("stribeck", "backlash"),
    experiments={
        "backlash": "hold after moving in each direction under the same load, then reverse the load at rest: "
        "stiction keeps the sign of the last move, backlash follows the sign of the torque",
    },
    phi_unit="1",
)
