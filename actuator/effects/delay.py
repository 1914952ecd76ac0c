"""``delay``: dead time between the command and the servo.

``phi = q_des(t) - q_des(t - delay)``, its coefficient about 1. A dead time shorter than the sample period can
resolve (a 5 ms dead time in a log sampled every 14 ms) still shows, as the command's lead over that time, about
``delay dq_des``: the velocity form (``delay = 0``, the form's limit) is ``phi = (q_des(t) - q_des(t - 1 tick)) /
period`` [rad/s], the command's velocity, and its coefficient is the dead time [s] (:func:`delay_of`). It is
offered where the period resolves no delay of the grid (2-20 ms need periods up to 1-10 ms).
On-line: ``q_des`` and its history (the commands of the last ``delay`` seconds, or the last tick's, and this
tick's): the model is then affine in ``q_des``, and :meth:`~servotau.actuator.online.OnlineModel.command`
solves ``q_des = q + model(q_des)`` for the feedforward.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, ResolvedGrid, fast_motion, steady_timing
from ..registry import Effect
from ..signals import Signals, delayed, ticks

ORDER = 140
SHAPES = tuple({"delay": v} for v in (0.0, 0.002, 0.005, 0.01, 0.02))  # [s] (0: the velocity form)
GRID = ResolvedGrid(SHAPES, ("delay",), zero_alone=True)  # the delays the sample period resolves, else the
# velocity form alone (beside a resolved delay it fits the derivative's error on a clean log: plant family seed 0 at
# 3 ms, delay 5.4 % of the held-out error with it, below 5 % without)


def delay(s: Signals, delay: float) -> np.ndarray:
    q_des = s["q_des"]
    dt = s.require_dt("delay")
    if delay == 0.0:
        return (q_des - delayed(q_des, 1, s.starts)) / dt
    return q_des - delayed(q_des, ticks(delay, dt), s.starts)


def delay_of(coefficient: float, shape: Mapping[str, float]) -> float:
    """The dead time [s] a fitted ``coefficient`` of ``shape`` gives: the coefficient itself in the velocity
    form, else the coefficient times the shape's delay."""
    return coefficient * (shape["delay"] or 1.0)


def shape_text(coefficient: float, shape: Mapping[str, float]) -> str:
    """The verdict's words for a fitted term: the dead time its coefficient gives, and the form."""
    dead_ms = 1e3 * delay_of(coefficient, shape)
    if shape["delay"] == 0.0:
        return f"velocity form: dead time {dead_ms:.3g} ms"
    return f"delay {1e3 * shape['delay']:.3g} ms: dead time {dead_ms:.3g} ms"


class DelayOnline:
    """On-line ``delay``: a buffer of the last commands (the velocity form: the last one, over the period)."""

    def __init__(self, shape: Mapping[str, float], period: float):
        self.velocity_form = shape["delay"] == 0.0
        self.period = period
        self.n = 1 if self.velocity_form else ticks(shape["delay"], period)  # commands kept
        self.buf: list[float] = []

    def _old(self, q_des: float) -> float:
        if len(self.buf) < self.n:
            return self.buf[0] if self.buf else q_des
        return self.buf[-self.n]

    def value(self, x: Mapping[str, float]) -> float:
        lead = x["q_des"] - self._old(x["q_des"])
        return lead / self.period if self.velocity_form else lead

    def commit(self, x: Mapping[str, float]) -> None:
        self.buf.append(x["q_des"])
        if len(self.buf) > self.n:
            del self.buf[0]


def needs(e: Excitation) -> str | None:
    """Steady time steps and fast motion (a delay the period does not resolve is tested in the velocity form)."""
    return steady_timing(e, "delay") or fast_motion(e)


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
    shape_text=shape_text,
    phi_unit={"delay 0 (the velocity form: the coefficient is the dead time)": "rad/s", "delay > 0": "rad"},
)
