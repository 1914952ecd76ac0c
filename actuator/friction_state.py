"""The friction state shared by the effects ``dahl`` and ``lugre`` (and the friction coefficient range).

Both integrate a normalised friction state ``z`` along the path travelled, ``dx = dq dt``, towards a steady
state ``z_ss(dq)`` (``sgn(dq)`` for Dahl, ``g(dq) sgn(dq)`` for LuGre) over a pre-sliding length ``x0 g`` [rad],
``dz/d|x| = (z_ss - z) / (x0 g)``, written per sample as the exact step over the tick's travel ``dx[k] = v[k] dt``
at its mean velocity ``v[k] = (dq[k-1] + dq[k]) / 2`` (trapezoid; ``dq[-1] = dq[0]``)::

    z[k] = a[k] z[k-1] + b[k],   a[k] = exp(-|v[k]| dt / (x0 g[k])),   b[k] = z_ss(v[k]) (1 - a[k]),   z[-1] = 0

(between reversals this is ``z = z_ss + (z_r - z_ss) exp(-|x - x_r| / (x0 g))``, the closed form from the state
``z_r`` at the reversal ``x_r``). The batch evaluation runs the linear time-varying recursion as a prefix scan
of the affine maps ``z -> a z + b`` (``log2 n`` vectorised passes, no per-sample loop); the on-line class runs
the same step one sample at a time. The path is integrated from the velocity signal, not from the encoder's
``q``: a quantised encoder's steps at rest would reverse the state at every count. At the first sample of each run
of the log (:attr:`~servotau.actuator.signals.Signals.starts`) the state restarts from ``z = 0`` with
``dq[-1] = dq[start]``, as at the log's first sample.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from .signals import Signals, delayed, run_bounds

FRICTION_COEFFICIENT = (0.0, float("inf"))
"""Friction opposes the motion: its coefficient ``k_tau F >= 0`` (a negative one would push the joint along)."""
X0_RATIO = 2.5  # ratio between neighbouring pre-sliding lengths of the grids
X0_MAX_SHAPES = 6  # most pre-sliding lengths a grid tries
X0_DEFAULT = (1e-4, 3e-4, 1e-3, 3e-3)  # [rad] the grid without a sampling period (the regressor then refuses)


def affine_scan(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``z[k] = a[k] z[k-1] + b[k]`` with ``z[-1] = 0``, for every ``k`` (prefix scan of the affine maps).

    Hillis-Steele doubling: after the pass of span ``d``, ``(a[k], b[k])`` is the composition of the maps
    ``k - 2d + 1 .. k``; ``|a| <= 1`` here, so the products only shrink (no overflow, no cancellation).
    """
    a = np.array(a, dtype=np.float64)
    b = np.array(b, dtype=np.float64)
    d = 1
    while d < len(a):
        b[d:] = a[d:] * b[:-d] + b[d:]  # right-hand sides read the previous pass (numpy copies on overlap)
        a[d:] = a[d:] * a[:-d]
        d *= 2
    return b


def steps(dq: np.ndarray, dt: float, x0: float, gain: np.ndarray | float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """``(a, b)`` of the recursion for the steady state ``gain sgn(dq)`` over ``x0 gain`` [rad]."""
    a = np.exp(-np.abs(dq) * dt / (x0 * gain))
    return a, np.sign(dq) * gain * (1.0 - a)


def step(dq: float, dt: float, x0: float, gain: float = 1.0) -> tuple[float, float]:
    """:func:`steps` of one sample."""
    a = math.exp(-abs(dq) * dt / (x0 * gain))
    return a, ((dq > 0) - (dq < 0)) * gain * (1.0 - a)


def state(s: Signals, what: str, x0: float, gain: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """The state ``z`` of every sample of ``s`` (``gain(dq)``: the steady state's magnitude, default 1)."""
    dt = s.require_dt(what)
    v = s.derived("dq", ("mean_velocity", s.starts), lambda dq: mean_velocity(dq, s.starts))  # once per log
    a, b = steps(v, dt, x0, 1.0 if gain is None else gain(v))
    a[list(s.starts[1:])] = 0.0  # z[start - 1] is not this run's: the state restarts from 0
    return affine_scan(a, b)


def mean_velocity(dq: np.ndarray, starts: Sequence[int] | None = None) -> np.ndarray:
    """``(dq[k-1] + dq[k]) / 2`` [rad/s], the mean velocity of each tick (``dq[-1] = dq[0]``, and likewise at
    each of ``starts``)."""
    return 0.5 * (dq + delayed(dq, 1, starts)) if len(dq) else dq.copy()


class OnlineState:
    """On-line :func:`state`: ``value`` is this tick's state (not committed), ``commit`` keeps it."""

    def __init__(self, x0: float, period: float, gain: Callable[[float], float] | None = None):
        self.x0, self.period, self.gain = x0, period, gain
        self.z = 0.0
        self.dq: float | None = None  # the last tick's velocity (None before the first)

    def _next(self, x: Mapping[str, float]) -> float:
        dq = x["dq"]
        v = 0.5 * ((dq if self.dq is None else self.dq) + dq)
        a, b = step(v, self.period, self.x0, 1.0 if self.gain is None else self.gain(v))
        return a * self.z + b

    def value(self, x: Mapping[str, float]) -> float:
        return self._next(x)

    def commit(self, x: Mapping[str, float]) -> None:
        self.z = self._next(x)
        self.dq = x["dq"]


def strokes(dq: np.ndarray, dt: float, starts: Sequence[int] | None = None) -> np.ndarray:
    """Travel [rad] between reversals of the motion (sign changes of ``dq`` beyond 5 % of its 95 % quantile of
    the whole log), within each run (a stroke ends with its run; a run with fewer than two samples beyond that
    has none), run by run."""
    v = np.quantile(np.abs(dq), 0.95) if len(dq) else 0.0
    if not v > 0:
        return np.zeros(0)
    sign = np.where(dq > 0.05 * v, 1, np.where(dq < -0.05 * v, -1, 0))
    bounds = np.asarray(run_bounds(len(dq), starts), dtype=np.intp).reshape(-1, 2)
    idx = np.flatnonzero(sign)
    run = np.searchsorted(bounds[:, 0], idx, side="right") - 1  # the run of each signed sample
    keep = np.bincount(run, minlength=len(bounds))[run] >= 2
    idx, run = idx[keep], run[keep]
    if idx.size == 0:
        return np.zeros(0)
    new_run = np.concatenate([[True], run[1:] != run[:-1]])
    reversal = ~new_run[1:] & (np.diff(sign[idx]) != 0)  # first sample of each new direction
    first_runs = run[new_run]
    edge_at = np.concatenate([idx[new_run], idx[1:][reversal], bounds[first_runs, 1]])
    edge_run = np.concatenate([first_runs, run[1:][reversal], first_runs])
    order = np.lexsort((edge_at, edge_run))  # each run's edges in time: its first signed sample, reversals, end
    edge_at, edge_run = edge_at[order], edge_run[order]
    travel = np.concatenate([[0.0], np.cumsum(np.abs(dq) * dt)])
    return np.diff(travel[edge_at])[edge_run[1:] == edge_run[:-1]]


def x0_grid(s: Signals, max_shapes: int = X0_MAX_SHAPES) -> tuple[float, ...]:
    """Pre-sliding lengths [rad] the data can resolve: from the travel of one sample at the median moving speed
    (shorter is Coulomb friction, settled within a tick) to half the median stroke between reversals (longer
    never settles: a spring), geometric with ratio :data:`X0_RATIO` (at most ``max_shapes``, thinned evenly)."""
    if s.dt is None or "dq" not in s:
        return X0_DEFAULT
    dq = s["dq"]
    speed = np.abs(dq)
    moving = speed[speed > 0.05 * np.quantile(speed, 0.95)] if len(speed) else speed
    lo = float(np.median(moving)) * s.dt if moving.size else 0.0
    st = strokes(dq, s.dt, s.starts)
    hi = 0.5 * float(np.median(st)) if st.size else 0.0
    if not (lo > 0 and math.isfinite(lo)):
        return X0_DEFAULT
    hi = max(hi, lo)
    k = int(math.floor(math.log(hi / lo) / math.log(X0_RATIO))) + 1
    values = lo * X0_RATIO ** np.arange(k)
    if k > max_shapes:
        values = values[np.round(np.linspace(0, k - 1, max_shapes)).astype(int)]
    return tuple(float(f"{v:.3g}") for v in values)
