"""``delay``: dead time between the command and the servo.

``phi = q_des(t) - q_des(t - delay)``. On-line: ``q_des`` and its history (the commands of the last ``delay``
seconds, and this tick's): the model is then affine in ``q_des``, and
:meth:`~servotau.actuator.online.OnlineModel.command` solves ``q_des = q + model(q_des)`` for the feedforward.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, ResolvedGrid, fast_motion, lag_resolved
from ..registry import Effect
from ..signals import Signals, delayed, ticks

ORDER = 140
SHAPES = tuple({"delay": v} for v in (0.002, 0.005, 0.01, 0.02))  # [s]
GRID = ResolvedGrid(SHAPES, ("delay",))  # the delays the sample period resolves


def delay(s: Signals, delay: float) -> np.ndarray:
    q_des = s["q_des"]
    return q_des - delayed(q_des, ticks(delay, s.require_dt("delay")), s.starts)


class DelayOnline:
    """On-line ``delay``: a buffer of the last commands."""

    def __init__(self, shape: Mapping[str, float], period: float):
        self.n = ticks(shape["delay"], period)
        self.buf: list[float] = []

    def _old(self, q_des: float) -> float:
        if len(self.buf) < self.n:
            return self.buf[0] if self.buf else q_des
        return self.buf[-self.n]

    def value(self, x: Mapping[str, float]) -> float:
        return x["q_des"] - self._old(x["q_des"])

    def commit(self, x: Mapping[str, float]) -> None:
        self.buf.append(x["q_des"])
        if len(self.buf) > self.n:
            del self.buf[0]


def needs(e: Excitation) -> str | None:
    """A delay the sample period resolves, and fast motion."""
    return lag_resolved(e, GRID, "delay") or fast_motion(e)


EFFECT = Effect(
    "delay", delay, GRID, ("t", "q_des"),
    signature="residual correlates with the command velocity: the servo sees q_des late",
    family="dynamics",
    description="dead time between the command and the servo",
    needs=needs,
    online=DelayOnline,
    history=True,
    online_signals="q_des (history: the commands of the last `delay` seconds, and this tick's)",
    confusable=("motor_lag", "elastic"),
    experiments={
        "motor_lag": "command steps or a chirp: a dead time shows a flat start and a phase lag growing linearly "
        "with frequency; a first-order lag responds at once and its phase saturates at 90 degrees",
    },
    phi_unit="rad",
)
