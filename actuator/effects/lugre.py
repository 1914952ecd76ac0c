"""``lugre``: LuGre friction, pre-sliding hysteresis with a Stribeck steady state (the bristle model).

The bristle state ``z`` [rad] follows ``dz/dt = v - |v| z / g(v)``, ``g(v) = (Fc + (Fs - Fc) exp(-(v/v_s)^2)) /
sigma0``; the friction is ``sigma0 z + sigma1 dz/dt + sigma2 v``. Normalised, ``w = sigma0 z / Fc`` follows
``dw/d|x| = (G(v) sgn(v) - w) / (x0 G(v))`` along the path ``dx = dq dt``, with ``G = 1 + (fs_ratio - 1)
exp(-(dq/v_s)^2)``, ``fs_ratio = Fs / Fc`` and ``x0 = Fc / sigma0`` [rad] the pre-sliding length: ``phi = w``
(``|w| <= fs_ratio``), the coefficient ``k_tau Fc``. Simplifications: the viscous ``sigma2 v`` is the base model's
``k_v dq``; the bristle damping ``sigma1 dz/dt`` is left out (it acts during the pre-sliding transient, over a
time ``sigma1 / sigma0`` far below a tick of a joint log, and its column is a derivative of ``w``: noise). Each
tick is the exact step at the tick's mean velocity (:mod:`~servotau.actuator.friction_state`). On-line: ``dq``
and its history (the state ``w``, the last ``dq``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, slow_motion
from ..friction_state import FRICTION_COEFFICIENT, OnlineState, state, x0_grid
from ..registry import Effect
from ..signals import Signals

ORDER = 36
FS_RATIO = (1.5, 3.0)  # breakaway over Coulomb friction Fs / Fc
V_S = (0.02, 0.08, 0.3)  # [rad/s] Stribeck velocities
X0_SHAPES = 4  # pre-sliding lengths tried (those of dahl's grid, thinned)


def grid(s: Signals) -> tuple[dict[str, float], ...]:
    """Pre-sliding lengths the log resolves (:func:`~servotau.actuator.friction_state.x0_grid`, thinned to
    ``X0_SHAPES``) x ``FS_RATIO`` x ``V_S``."""
    return tuple({"x0": x0, "fs_ratio": r, "v_s": v}
                 for x0 in x0_grid(s, X0_SHAPES) for r in FS_RATIO for v in V_S)


GRID = grid


def _gain(fs_ratio: float, v_s: float):
    return lambda dq: 1.0 + (fs_ratio - 1.0) * np.exp(-((dq / v_s) ** 2))


def lugre(s: Signals, x0: float, fs_ratio: float, v_s: float) -> np.ndarray:
    return state(s, "lugre", x0, _gain(fs_ratio, v_s))


class LugreOnline(OnlineState):
    """On-line ``lugre``: the normalised bristle state ``w``, one exact step per tick."""

    def __init__(self, shape: Mapping[str, float], period: float):
        r, v_s = shape["fs_ratio"], shape["v_s"]
        super().__init__(shape["x0"], period, lambda dq: 1.0 + (r - 1.0) * math.exp(-((dq / v_s) ** 2)))


def needs(e: Excitation) -> str | None:
    """Reversals of the motion (the pre-sliding state) and slow motion (the Stribeck steady state)."""
    if e.velocity_reversals < 2:
        return (f"only {e.velocity_reversals} velocity reversals: expected >= 2 (the bristle state is set at each "
                "reversal; best: small back-and-forth moves)")
    slow = slow_motion(e)
    return f"{slow} (the Stribeck steady state needs slow speeds)" if slow else None


EFFECT = Effect(
    "lugre", lugre, GRID, ("t", "dq"),
    signature="after each reversal the residual rises over a short travel x0 to a breakaway peak that decays "
    "with speed (Stribeck); at rest it keeps the level of the last move",
    family="velocity",
    description="LuGre friction: a bristle state with pre-sliding hysteresis and a Stribeck steady state",
    needs=needs,
    online=LugreOnline,
    history=True,
    online_signals="dq (history: the bristle state and the last dq)",
    coefficient_range=FRICTION_COEFFICIENT,
    confusable=("stribeck", "dahl", "stiction"),
    experiments={
        "stribeck": "small back-and-forth moves at a low constant speed: LuGre friction grows with the travel "
        "since the reversal over x0, Stribeck friction is a function of the speed alone (full at once)",
        "dahl": "constant-velocity ramps at several slow speeds (0.01 to 0.3 rad/s): the LuGre steady friction "
        "falls from Fs to Fc with speed, the Dahl steady friction is Fc at every speed",
        "stiction": "hold, then move slowly by a small amount against the last move: LuGre friction changes "
        "continuously with the travel, stiction breaks away at once",
    },
    phi_unit="1",
)
