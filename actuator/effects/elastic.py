"""``elastic``: elastic gear: the motor inertia acts behind the spring, outside the link torque.

``phi = a``, the acceleration (centred SG of ``q`` over ``window``, or the estimator's) delayed by ``lag`` like
the torque estimate (:func:`~servotau.actuator.signals.inertia`). On-line: ``ddq`` (the estimator's
acceleration; history: the last ``lag`` seconds of it).
"""

from __future__ import annotations

import numpy as np

from ..excitation import Excitation, ResolvedGrid, fast_motion, lag_resolved
from ..registry import Effect
from ..signals import INERTIA_LAGS, OnlineInertia, Signals, inertia

ORDER = 120
SHAPES = tuple({"window": w, "lag": lag} for w in (0.011, 0.021, 0.041, 0.081) for lag in INERTIA_LAGS)
GRID = ResolvedGrid(SHAPES, ("window", "lag"))  # the acceleration windows and lags the sample period resolves


def elastic(s: Signals, window: float, lag: float = 0.0) -> np.ndarray:
    return inertia(s, window, lag)


def needs(e: Excitation) -> str | None:
    """An acceleration window the sample period resolves, and fast motion."""
    return lag_resolved(e, GRID, "acceleration window") or fast_motion(e)


EFFECT = Effect(
    "elastic", elastic, GRID, ("q",),
    signature="residual proportional to the acceleration (rotor inertia behind a compliant gear)",
    family="dynamics",
    description="elastic gear: the motor inertia acts behind the spring, outside the link torque",
    needs=needs,
    online=OnlineInertia,
    online_signals="ddq (the estimator's acceleration; history: the last `lag` seconds of it)",
    signal_substitutes={"q": "ddq"},
    confusable=("backlash", "motor_lag", "delay"),
    experiments={
        "backlash": "reverse the torque slowly at rest and compare a link-side angle with the motor encoder: "
        "backlash jumps by the play at zero torque, an elastic gear deflects in proportion to the torque (model the "
        "deflection q_motor - q_link against the torque: play shows as a 'deadzone' step of half the play)",
        "motor_lag": "a chirp of the command at constant load: the acceleration term grows with the square of the "
        "frequency, a lag's phase saturates",
        "delay": "command steps (or a chirp): a dead time shows a flat start, the rotor inertia a response to the "
        "acceleration from the first sample",
    },
    phi_unit="rad/s^2",
)
