"""``delay``: dead time between the command and the servo.

``phi = q_des(t) - q_des(t - delay)``. On-line: ``q_des`` and its history (the commands of the last ``delay``
seconds, and this tick's): the model is then affine in ``q_des``, and
:meth:`~servotau.actuator.online.OnlineModel.command` solves ``q_des = q + model(q_des)`` for the feedforward.

A delay shorter than ``RESOLVE_PERIODS`` sample periods is not one of the grid's shapes at that period; the one-tick
form (``delay = 0``: ``q_des(t) - q_des(t - 1 tick)``) stands for it. Where the command moves smoothly at the
sample rate, ``q_des(t - d)`` for ``d`` within a tick is the linear interpolation ``q_des(t) - (d / period)
(q_des(t) - q_des(t - 1 tick))``: the form's coefficient is ``d / period`` (:func:`delay_of`). A command that
jumps between samples (steps) has no such interpolation, and a delay below two periods cannot be told there; nor in
a log sampled slower than the grid's longest delay, where the servo's whole response (its lags and inertia) falls
within a tick and the form stands for any of them.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import RESOLVE_PERIODS, Excitation, ResolvedGrid, fast_motion, lag_resolved, resolvable, steady_timing
from ..registry import Effect
from ..signals import Signals, delayed, ticks

ORDER = 140
SHAPES = tuple({"delay": v} for v in (0.002, 0.005, 0.01, 0.02))  # [s]
RESOLVED = ResolvedGrid(SHAPES, ("delay",))  # the delays the sample period resolves
ONE_TICK = {"delay": 0.0}  # the one-tick form (see the module doc)
LONGEST = SHAPES[-1]["delay"]  # [s] longest sample period of the one-tick form
SMOOTH = 0.5  # largest command curvature (Excitation.command_curvature) that the one-tick form interpolates: a
# sine sampled at least 12.6 times a period (steps give 1.4)


def grid(s: Signals) -> tuple[Mapping[str, float], ...]:
    """The delays the sample period resolves, and the one-tick form when the grid's shortest one is not resolved
    (and the period is at most the grid's longest delay); the whole grid when neither (``needs`` then says why)."""
    dt = s.dt
    resolved = tuple(g for g in SHAPES if resolvable(g, ("delay",), dt))
    if not dt or resolved[:1] == SHAPES[:1] or dt > LONGEST:
        return resolved or SHAPES
    return (*resolved, ONE_TICK)


def delay_of(coefficient: float, shape: Mapping[str, float], period: float) -> float:
    """[s] The dead time a fitted ``delay`` term stands for: ``coefficient`` times its shape's delay in whole ticks
    (the one-tick form: one period; a delay shorter than the shape's is interpolated, see the module doc)."""
    return coefficient * ticks(shape["delay"], period) * period


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
    """A delay the sample period resolves, or a command smooth enough for the one-tick form; and fast motion."""
    return lag_resolved(e, RESOLVED, "delay") and interpolated(e) or fast_motion(e)


def interpolated(e: Excitation) -> str | None:
    """Why the one-tick form cannot stand for a delay below two periods: time steps that jitter, or a command that
    turns too much between samples (see the module doc)."""
    why = steady_timing(e, "delay")
    if why is not None or e.period is None:
        return why
    head = (f"cannot tell: the sample period {1e3 * e.period:.3g} ms resolves no delay of the grid (delay "
            f"{1e3 * SHAPES[0]['delay']:.3g}-{1e3 * LONGEST:.3g} ms, each needs {RESOLVE_PERIODS:g} periods)")
    if e.period > LONGEST:
        return f"{head}, and the servo's whole response falls within a sample"
    if e.command_curvature is None or e.command_curvature > SMOOTH:
        turn = "" if e.command_curvature is None else f" by {e.command_curvature:.2g}"
        return (f"{head}, and the command turns{turn} between samples (its curvature; at most {SMOOTH:g} to "
                "interpolate a shorter delay)")
    return None


EFFECT = Effect(
    "delay", delay, grid, ("t", "q_des"),
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
