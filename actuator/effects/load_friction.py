"""``load_friction``: friction growing with the transmitted load.

``phi = |tau| s(dq, v_eps)``. On-line: ``tau``, ``dq``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, both_directions, has_torque
from ..registry import Effect
from ..signals import V_EPS, Signals, sign_of, smooth_sign_scalar

ORDER = 70
GRID = tuple({"v_eps": v} for v in V_EPS[1:])


def load_friction(s: Signals, v_eps: float) -> np.ndarray:
    return np.abs(s["tau"]) * sign_of(s, "dq", v_eps)


def scalar(x: Mapping[str, float], v_eps: float) -> float:
    return abs(x["tau"]) * smooth_sign_scalar(x["dq"], v_eps)


def needs(e: Excitation) -> str | None:
    """Loaded motion (high torque while moving), in both directions."""
    if e.torque_range is None:
        return has_torque(e)
    if e.loaded_motion < 0.05:
        return f"loaded motion {100 * e.loaded_motion:.0f} %: expected >= 5 % of moving samples under high torque"
    return both_directions(e)


EFFECT = Effect(
    "load_friction", load_friction, GRID, ("tau", "dq"),
    signature="residual against torque split by velocity sign: a V (|tau|) with opposite signs for dq > 0 and "
    "dq < 0",
    family="torque",
    description="friction growing with the transmitted load",
    needs=needs,
    scalar=scalar,
    online_signals="tau, dq",
    confusable=("direction_gain",),
    phi_unit="N m",
)
