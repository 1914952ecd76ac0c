"""``coulomb_asym``: Coulomb friction larger in one direction than in the other.

``phi = |s(dq, v_eps)|``: the same offset on both sides of ``dq = 0`` while moving. On-line: ``dq``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, both_directions
from ..registry import Effect
from ..signals import V_EPS, Signals, sign_of, smooth_sign_scalar

ORDER = 20
GRID = tuple({"v_eps": v} for v in V_EPS)


def coulomb_asym(s: Signals, v_eps: float) -> np.ndarray:
    return np.abs(sign_of(s, "dq", v_eps))


def scalar(x: Mapping[str, float], v_eps: float) -> float:
    return abs(smooth_sign_scalar(x["dq"], v_eps))


def needs(e: Excitation) -> str | None:
    return both_directions(e)


EFFECT = Effect(
    "coulomb_asym", coulomb_asym, GRID, ("dq",),
    signature="residual against velocity: the same offset on both sides of dq = 0 while moving, none at rest",
    family="velocity",
    description="Coulomb friction larger in one direction than in the other",
    needs=needs,
    scalar=scalar,
    online_signals="dq",
    phi_unit="1",
)
