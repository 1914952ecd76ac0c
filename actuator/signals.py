"""The signals an effect regressor reads, the causal filters shared by batch and on-line evaluation, and the
helpers several effects share (smoothed sign, the command's lead, the acceleration, on-line lags and buffers).

An effect is a function of :class:`Signals`, a read-only mapping from signal name to a 1-D array
(one sample per tick). Standard names:

- ``t`` [s], ``q`` [rad], ``q_des`` [rad], ``tau`` [N m], ``dq`` [rad/s], ``ddq`` [rad/s^2];
- ``u`` [rad]: the linear part of the current model, ``k_tau tau + k_v dq``: the servo error the paper's
  model expects (dead zone, direction gain and thermal drift act on it);
- every other column of the log, under its own name (for user-defined effects).

Filters with memory (delays, first-order lags, the direction latch, the limit detector with hysteresis) are
written as one-step recursions, evaluated here over a whole array and by
:mod:`~servotau.actuator.online` one sample at a time, so both give the same numbers.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping

import numpy as np
from scipy.signal import lfilter

from servotau.errors import IdentificationError
from servotau.signal.savgol import savgol_centred

STANDARD = ("t", "q", "q_des", "tau", "dq", "ddq", "u")


class Signals(Mapping[str, np.ndarray]):
    """Named 1-D signals of equal length, sampled every ``dt`` seconds (None if unknown).

    Entries can be given lazily as zero-argument callables; they are computed on first access.
    Filtered versions of a signal (:meth:`derived`) are computed once for this object and the copies
    :meth:`with_columns` makes of it, as long as they hold the same array.
    """

    def __init__(
        self,
        columns: Mapping[str, np.ndarray | Callable[[], np.ndarray]],
        dt: float | None,
        n: int,
        *,
        memo: dict | None = None,
    ):
        self._cols = dict(columns)
        self.dt = dt
        self.n = int(n)
        self._memo = {} if memo is None else memo  # (source, key) -> (source array, derived array)

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._cols:
            raise IdentificationError(f"signal '{name}' is not available: expected one of {sorted(self._cols)}")
        v = self._cols[name]
        if callable(v):
            v = np.asarray(v(), dtype=np.float64)
            self._cols[name] = v
        return v

    def __contains__(self, name: object) -> bool:
        return name in self._cols

    def __iter__(self) -> Iterator[str]:
        return iter(self._cols)

    def __len__(self) -> int:
        return len(self._cols)

    def with_columns(self, **columns: np.ndarray | Callable[[], np.ndarray]) -> Signals:
        """A copy with ``columns`` added or replaced (e.g. ``u`` of another model)."""
        return Signals({**self._cols, **columns}, self.dt, self.n, memo=self._memo)

    def derived(self, source: str, key: tuple, compute: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """``compute(self[source])`` (read-only), computed once per ``key`` (what the computation is, e.g.
        ``("ddq", window)``) while ``source`` is the same array, here and in the copies of :meth:`with_columns`:
        a diagnosis filters the same ``q`` with the same few windows in every fit."""
        x = self[source]
        hit = self._memo.get((source, key))
        if hit is not None and hit[0] is x:
            return hit[1]
        y = compute(x)
        y.setflags(write=False)
        self._memo[(source, key)] = (x, y)
        return y

    def require_dt(self, what: str) -> float:
        """The sampling period [s], or raise naming ``what`` needs it."""
        if self.dt is None:
            raise IdentificationError(f"{what}: needs a sampling period: expected a time column in the log")
        return self.dt


def ticks(seconds: float, dt: float) -> int:
    """``seconds`` as a whole number of samples (at least 1)."""
    return max(1, int(round(seconds / dt)))


def delayed(x: np.ndarray, n: int) -> np.ndarray:
    """``x`` delayed by ``n`` samples, the first value repeated before the start."""
    if n <= 0:
        return x.copy()
    if n >= len(x):
        return np.full_like(x, x[0])
    return np.concatenate([np.full(n, x[0]), x[:-n]])


def lowpass_gain(time_constant: float, dt: float) -> float:
    """Gain ``a`` of ``y += a (x - y)``, the backward-Euler first-order lag of ``time_constant`` [s]."""
    return dt / (time_constant + dt)


def lowpass(x: np.ndarray, time_constant: float, dt: float, y0: float | None = None) -> np.ndarray:
    """First-order lag ``y[k] = y[k-1] + a (x[k] - y[k-1])`` with ``y[-1] = y0`` (default ``x[0]``)."""
    a = lowpass_gain(time_constant, dt)
    y0 = float(x[0]) if y0 is None else y0
    y, _ = lfilter([a], [1.0, -(1.0 - a)], x, zi=[(1.0 - a) * y0])
    return y


def direction_latch(dq: np.ndarray, threshold: float) -> np.ndarray:
    """Sign of the last velocity with ``|dq| > threshold`` [rad/s] (0 before any motion)."""
    return sign_latch(dq, np.abs(dq) > threshold)


def sign_latch(x: np.ndarray, flag: np.ndarray) -> np.ndarray:
    """Sign of ``x`` at the last sample where ``flag`` is True (0 before the first)."""
    idx = np.where(flag, np.arange(len(x)), -1)
    np.maximum.accumulate(idx, out=idx)
    out = np.sign(x[np.maximum(idx, 0)])
    out[idx < 0] = 0.0
    return out


def run_onsets(flag: np.ndarray) -> np.ndarray:
    """Index of the first sample of the run of ``True`` each sample belongs to (-1 before the first run;
    meaningful where ``flag`` is True)."""
    idx = np.arange(len(flag))
    start = flag & ~np.concatenate([[False], flag[:-1]])
    out = np.where(start, idx, -1)
    np.maximum.accumulate(out, out=out)
    return out


def since_onset(x: np.ndarray, flag: np.ndarray) -> np.ndarray:
    """``x - x[onset]`` where ``flag`` is True, ``onset`` the first sample of the run it belongs to; 0 elsewhere."""
    return np.where(flag, x - x[np.maximum(run_onsets(flag), 0)], 0.0)


def hysteresis(x: np.ndarray, on: float, off: float) -> np.ndarray:
    """A detector with hysteresis: True from the first ``x > on`` until ``x <= off`` (``off <= on``).

    One-step recursion ``s[k] = x[k] > (off if s[k-1] else on)``, written over the whole array: a sample
    is on if ``x > off`` and some sample of the same run of ``x > off`` reached ``on`` before it (or at it).
    """
    if off > on:
        raise IdentificationError(f"hysteresis: off = {off!r} > on = {on!r}: expected off <= on")
    above_off = x > off
    idx = np.arange(len(x))
    last_on = np.maximum.accumulate(np.where(x > on, idx, -1))
    return above_off & (last_on >= run_onsets(above_off)) & (last_on >= 0)


# -- helpers shared by several effects -----------------------------------------------------------------
V_EPS = (0.0, 0.005, 0.01, 0.02, 0.05)  # [rad/s] sign smoothing tried by the grids (0: plain sign)
INERTIA_LAGS = (0.0, 0.002, 0.005)  # [s] delays of the inertia term tried by the grids (that of the torque estimate)


def smooth_sign(x: np.ndarray, v: float) -> np.ndarray:
    """``tanh(x / v)``, or ``sign(x)`` for ``v <= 0``."""
    return np.sign(x) if v <= 0.0 else np.tanh(x / v)


def smooth_sign_scalar(x: float, v: float) -> float:
    """:func:`smooth_sign` of one sample."""
    return (x > 0) - (x < 0) if v <= 0.0 else math.tanh(x / v)


def command_lead(s: Signals) -> np.ndarray:
    """``q_des(t - 1 tick) - q(t)`` [rad]: the error the servo has to close at the start of the tick, up to
    the previous command (the integral of ``dq_des - dq``; this tick's command is not read)."""
    return delayed(s["q_des"], 1) - s["q"]


def sample_lead(x: Mapping[str, float], q_des_prev: float | None) -> float:
    """:func:`command_lead` of one sample: the last tick's command (this tick's on the first) minus ``q``."""
    return (x["q_des"] if q_des_prev is None else q_des_prev) - x["q"]


def acceleration(s: Signals, window: float) -> np.ndarray:
    """The acceleration [rad/s^2]: an estimate given with the data (``ddq_est``: an acceleration column of
    the log, or the controller's estimator on-line), else the centred SG second derivative of ``q`` over
    ``window`` [s] (order 3)."""
    if "ddq_est" in s:
        return s["ddq_est"]
    if window <= 0.0:
        return s["ddq"]
    dt = s.require_dt("acceleration")
    w = max(5, int(round(window / dt)) | 1)
    if w > s.n:
        return s["ddq"]
    return s.derived("q", ("ddq", w, dt), lambda q: savgol_centred(q, w, 3, dt, deriv=2))


def inertia(s: Signals, window: float, lag: float = 0.0) -> np.ndarray:
    """The acceleration of :func:`acceleration`, delayed by ``lag`` [s] like the torque estimate.

    The servo torque is the link torque plus the rotor's inertia torque ``J ddq``; when the torque column
    is an estimate that lags the encoders (an estimator's delay), only an equally delayed inertia term
    completes it into the (smooth) servo torque of that earlier instant. ``lag = 0``: no delay.
    """
    a = acceleration(s, window)
    if lag <= 0.0:
        return a
    return delayed(a, ticks(lag, s.require_dt("the lag of the inertia term")))


def sample_acceleration(x: Mapping[str, float]) -> float:
    """The acceleration of one sample: the estimator's (``ddq_est``) if given, else ``ddq``."""
    return x["ddq_est"] if "ddq_est" in x else x["ddq"]


class OnlineLag:
    """``y += a (x - y)`` on a signal of the sample (on-line :func:`lowpass`); effects say what x is."""

    def __init__(self, time_constant: float, period: float, y0: float | None):
        self.a = lowpass_gain(time_constant, period)
        self.y = y0

    def _next(self, x: float) -> float:
        y = x if self.y is None else self.y  # first sample: y[-1] = x[0] unless y0 was given
        return y + self.a * (x - y)


class OnlineInertia:
    """On-line :func:`inertia`: the estimator's acceleration, delayed by the shape's ``lag`` (a buffer)."""

    def __init__(self, shape: Mapping[str, float], period: float):
        lag = shape.get("lag", 0.0)
        self.n = ticks(lag, period) if lag > 0.0 else 0
        self.buf: list[float] = []

    def _acc(self, x: Mapping[str, float]) -> float:
        a = sample_acceleration(x)
        if self.n == 0:
            return a
        if len(self.buf) < self.n:
            return self.buf[0] if self.buf else a
        return self.buf[-self.n]

    def value(self, x: Mapping[str, float]) -> float:
        return self._acc(x)

    def commit(self, x: Mapping[str, float]) -> None:
        if self.n:
            self.buf.append(sample_acceleration(x))
            if len(self.buf) > self.n:
                del self.buf[0]
