"""``stribeck``: the Stribeck friction curve, breakaway friction decaying with speed to a Coulomb level.

``phi = s(dq, v_eps) (level + (1 - level) exp(-(dq / v_s)^2))``, ``v_s`` [rad/s] the Stribeck velocity, ``level``
the Coulomb friction as a fraction of the breakaway friction (the coefficient). ``level = 0`` is the excess over a
Coulomb term the model already has; a model without one needs the whole curve, whose Coulomb part would otherwise be
named ``coulomb`` while the excess, a few percent of the error, goes unnamed. The curve contains ``coulomb``
(``nests``): it is ranked above it only where its extra freedom pays in every held-out block. On-line: ``dq``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, both_directions, slow_and_fast
from ..registry import Effect
from ..signals import Signals, bell_of, sign_of, smooth_sign_scalar

ORDER = 30
V_S = (0.01, 0.02, 0.04, 0.08, 0.16, 0.32)  # [rad/s] Stribeck velocities
LEVELS = (0.0, 0.3, 0.6)  # Coulomb friction / breakaway friction
GRID = tuple({"v_s": v, "v_eps": e, "level": c} for c in LEVELS for v in V_S
             for e in ((0.005, 0.01, 0.02) if c == 0.0 else (0.01,)))  # the excess's sign smoothing matters most


def stribeck(s: Signals, v_s: float, v_eps: float, level: float = 0.0) -> np.ndarray:
    return sign_of(s, "dq", v_eps) * (level + (1.0 - level) * bell_of(s, "dq", v_s))


def scalar(x: Mapping[str, float], v_s: float, v_eps: float, level: float = 0.0) -> float:
    return smooth_sign_scalar(x["dq"], v_eps) * (level + (1.0 - level) * math.exp(-((x["dq"] / v_s) ** 2)))


def needs(e: Excitation) -> str | None:
    """Slow and fast motion: the Stribeck curve needs several speeds."""
    return slow_and_fast(e) or both_directions(e)


EFFECT = Effect(
    "stribeck", stribeck, GRID, ("dq",),
    signature="residual against velocity: opposite peaks just above and below dq = 0, fading beyond v_s",
    family="velocity",
    description="breakaway friction decaying with speed to a Coulomb level (the Stribeck curve)",
    needs=needs,
    scalar=scalar,
    online_signals="dq",
    confusable=("stiction", "coulomb"),
    nests=("coulomb",),
    experiments={
        "stiction": "constant-velocity ramps at several slow speeds (0.01 to 0.3 rad/s) and holds approached from "
        "both sides: Stribeck friction decays with speed, stiction acts only at rest with the sign of the last move",
        "coulomb": "constant-velocity ramps at several speeds: the Stribeck excess fades with speed, Coulomb "
        "friction stays",
    },
    phi_unit="1",
)
