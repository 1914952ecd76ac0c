"""``backlash``: compliant gear with play: the rotor inertia acts behind the gear, freely inside the play.

``phi = a (1 + gain exp(-(tau / tau_band)^2))``, ``a`` the acceleration (centred SG of ``q`` over ``window``, or
the estimator's) delayed by ``lag`` like the torque estimate (:func:`~servotau.actuator.signals.inertia`).
On-line: ``tau``, ``ddq`` (the estimator's acceleration; history: the last ``lag`` seconds of it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, ResolvedGrid, has_torque, lag_resolved
from ..registry import Effect
from ..signals import INERTIA_LAGS, OnlineInertia, Signals, inertia

ORDER = 80
SHAPES = tuple({"window": w, "tau_band": b, "gain": g, "lag": lag}
               for w in (0.011, 0.021) for b in (2.0, 5.0, 10.0) for g in (1.0, 3.0) for lag in INERTIA_LAGS)
GRID = ResolvedGrid(SHAPES, ("window", "lag"))  # the acceleration windows and lags the sample period resolves


def backlash(s: Signals, window: float, tau_band: float, gain: float, lag: float = 0.0) -> np.ndarray:
    return inertia(s, window, lag) * (1.0 + gain * np.exp(-((s["tau"] / tau_band) ** 2)))


class BacklashOnline(OnlineInertia):
    """On-line ``backlash``: the delayed acceleration, stronger near zero torque."""

    def __init__(self, shape: Mapping[str, float], period: float):
        super().__init__(shape, period)
        self.tau_band, self.gain = shape.get("tau_band"), shape.get("gain", 0.0)

    def value(self, x: Mapping[str, float]) -> float:
        a = self._acc(x)
        if self.tau_band is None:
            return a
        return a * (1.0 + self.gain * math.exp(-((x["tau"] / self.tau_band) ** 2)))


def needs(e: Excitation) -> str | None:
    """An acceleration window the sample period resolves, and torque reversals: the gear must cross its play."""
    if e.torque_range is None:
        return has_torque(e)
    if e.torque_reversals < 2:
        return (f"{e.torque_reversals} torque sign changes beyond +-{e.tau_threshold:.2g} N m: expected >= 2 (the gear "
                "must cross its play)")
    return lag_resolved(e, GRID, "acceleration window")


EFFECT = Effect(
    "backlash", backlash, GRID, ("q", "tau"),
    signature="residual follows the motor acceleration, more strongly while the torque is near zero (the rotor "
    "crosses the play unloaded)",
    family="dynamics",
    description="compliant gear with play: the rotor inertia acts behind the gear, freely inside the play",
    needs=needs,
    online=BacklashOnline,
    online_signals="tau, ddq (the estimator's acceleration; history: the last `lag` seconds of it)",
    signal_substitutes={"q": "ddq"},
    confusable=("elastic", "deadzone"),
    phi_unit="rad/s^2",
)
