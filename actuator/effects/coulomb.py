"""``coulomb``: Coulomb friction, a constant torque opposing the motion.

``phi = s(dq, v_eps)``, the sign of the velocity smoothed over ``v_eps`` [rad/s] (0: plain sign). A motor file's
``k_c`` is this term with ``v_eps = 0``. On-line: ``dq``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, both_directions
from ..registry import Effect
from ..signals import V_EPS, Signals, sign_of, smooth_sign_scalar

ORDER = 10
GRID = tuple({"v_eps": v} for v in V_EPS)


def coulomb(s: Signals, v_eps: float) -> np.ndarray:
    return sign_of(s, "dq", v_eps)


def scalar(x: Mapping[str, float], v_eps: float) -> float:
    return smooth_sign_scalar(x["dq"], v_eps)


def needs(e: Excitation) -> str | None:
    return both_directions(e)


EFFECT = Effect(
    "coulomb", coulomb, GRID, ("dq",),
    signature="residual against velocity: a step at dq = 0, equal and opposite on both sides, flat beyond",
    family="velocity",
    description="Coulomb friction: a constant torque opposing the motion",
    needs=needs,
    scalar=scalar,
    online_signals="dq",
    confusable=("deadzone", "stribeck"),
    phi_unit="1",
)
