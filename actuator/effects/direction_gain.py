"""``direction_gain``: servo gain that changes with the direction of motion.

``phi = s(dq, v_eps) u``, ``u = k_tau tau + k_v dq`` the linear part of the model. On-line: ``tau``, ``dq``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, both_directions
from ..registry import Effect
from ..signals import V_EPS, Signals, sign_of, smooth_sign_scalar

ORDER = 60
GRID = tuple({"v_eps": v} for v in V_EPS[1:])


def direction_gain(s: Signals, v_eps: float) -> np.ndarray:
    return sign_of(s, "dq", v_eps) * s["u"]


def scalar(x: Mapping[str, float], v_eps: float) -> float:
    return smooth_sign_scalar(x["dq"], v_eps) * x["u"]


def needs(e: Excitation) -> str | None:
    return both_directions(e)


EFFECT = Effect(
    "direction_gain", direction_gain, GRID, ("tau", "dq", "u"),
    signature="residual proportional to u with opposite slopes for dq > 0 and dq < 0",
    family="servo_error",
    description="servo gain that changes with the direction of motion",
    needs=needs,
    scalar=scalar,
    online_signals="tau, dq",
    confusable=("load_friction",),
    experiments={
        "load_friction": "move in both directions under torques of both signs (push the limb while it moves): a "
        "direction gain follows the sign of u, load friction the magnitude |tau|",
    },
    phi_unit="target",
)
