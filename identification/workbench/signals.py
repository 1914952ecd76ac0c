"""The signals an effect regressor reads, and the causal filters shared by batch and on-line evaluation.

An effect is a function of :class:`Signals`, a read-only mapping from signal name to a 1-D array
(one sample per tick). Standard names:

- ``t`` [s], ``q`` [rad], ``q_des`` [rad], ``tau`` [N m], ``dq`` [rad/s], ``ddq`` [rad/s^2];
- ``u`` [rad]: the linear part of the current model, ``k_tau tau + k_v dq``: the servo error the paper's
  model expects (dead zone, direction gain and thermal drift act on it);
- every other column of the log, under its own name (for user-defined effects).

Filters with memory (delays, first-order lags, the direction latch, the limit detector with hysteresis) are
written as one-step recursions, evaluated here over a whole array and by
:mod:`~servotau.identification.workbench.online` one sample at a time, so both give the same numbers.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping

import numpy as np
from scipy.signal import lfilter

from servotau.errors import IdentificationError

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
