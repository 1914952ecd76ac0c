"""``dahl``: Dahl friction, pre-sliding hysteresis: the friction builds up over a short travel after each reversal.

``phi = z``, the normalised Dahl state (``|z| <= 1``, the friction over its Coulomb level) integrated along the
path ``dx = dq dt``: ``dz/dx = (1 - z sgn(dx)) / x0``, ``x0 = Fc / sigma`` [rad] the pre-sliding length (the
travel over which the friction settles, ``sigma`` the bristles' stiffness). After a reversal at ``z = -1``,
``z = 1 - 2 exp(-|x - x_r| / x0)``; at rest ``z`` holds. Each tick is the exact step at the tick's mean velocity
(:mod:`~servotau.actuator.friction_state`). On-line: ``dq`` and its history (the state ``z``, the last ``dq``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation
from ..friction_state import FRICTION_COEFFICIENT, OnlineState, state, x0_grid
from ..registry import Effect
from ..signals import Signals

ORDER = 35


def grid(s: Signals) -> tuple[dict[str, float], ...]:
    """Pre-sliding lengths the log resolves (:func:`~servotau.actuator.friction_state.x0_grid`)."""
    return tuple({"x0": x0} for x0 in x0_grid(s))


GRID = grid


def dahl(s: Signals, x0: float) -> np.ndarray:
    return state(s, "dahl", x0)


class DahlOnline(OnlineState):
    """On-line ``dahl``: the state ``z``, one exact step per tick."""

    def __init__(self, shape: Mapping[str, float], period: float):
        super().__init__(shape["x0"], period)


def needs(e: Excitation) -> str | None:
    """Reversals of the motion: the hysteresis shows in the first ``x0`` of travel after each."""
    if e.velocity_reversals < 2:
        return (f"only {e.velocity_reversals} velocity reversals: expected >= 2 (pre-sliding hysteresis shows in "
                "the first x0 of travel after a reversal; best: small back-and-forth moves)")
    return None


EFFECT = Effect(
    "dahl", dahl, GRID, ("t", "dq"),
    signature="after each reversal the residual swings from one friction level to the other over a short travel "
    "x0, not at once; at rest it keeps the level of the last move (hysteresis against position)",
    family="velocity",
    description="Dahl friction: pre-sliding hysteresis, the friction builds up over a travel x0 after each reversal",
    needs=needs,
    online=DahlOnline,
    history=True,
    online_signals="dq (history: the friction state z and the last dq)",
    coefficient_range=FRICTION_COEFFICIENT,
    confusable=("coulomb", "stiction", "elastic", "backlash", "motor_lag", "lugre"),
    experiments={
        "coulomb": "small back-and-forth moves (amplitudes from 0.1 x0 to 10 x0) at a low constant speed: Dahl "
        "friction grows with the travel since the reversal (1 - 2 exp(-travel / x0)), Coulomb friction steps at "
        "the reversal whatever the travel",
        "stiction": "hold, then move slowly by a small amount in the same and in the opposite direction: Dahl "
        "friction changes continuously with the travel from the hold (in both directions), stiction breaks away at "
        "once in the direction of the last move and is released",
        "elastic": "two slow triangular position sweeps of different amplitude: Dahl hysteresis saturates at the "
        "Coulomb level after a few x0 of travel, an elastic gear's deflection keeps following the torque",
        "motor_lag": "back-and-forth moves of the same amplitude at two speeds (e.g. 0.02 and 0.2 rad/s): the Dahl "
        "transition after a reversal takes the same travel x0 at both (its duration scales as 1 / speed), a lag "
        "takes the same time",
        "backlash": "small moves at constant slow speed under a steady load: the Dahl state follows the travel "
        "whatever the load, the play of a backlash is crossed only where the torque changes sign",
    },
    phi_unit="1",
)
