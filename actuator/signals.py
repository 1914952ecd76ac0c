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

Runs: a log can hold several stretches of consecutive samples (recordings joined end to end, a gap in the time
stamps, dropped rows): :attr:`Signals.starts` gives the first sample of each. Every filter that reads the past
(or, centred, the future) restarts at each start: its state is reset as at the first sample of a log, and no
sample of another run is read. The centred acceleration fits its polynomial to the run's first (last) full
window at the run's edges, as at a log's ends (one-sided, no delay): a log of several runs gives the same columns
as each run processed alone and concatenated, and no row is dropped or down-weighted.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence

import numpy as np

from servotau.errors import IdentificationError
from servotau.signal.savgol import savgol_centred, savgol_centred_runs

STANDARD = ("t", "q", "q_des", "tau", "dq", "ddq", "u")


class Signals(Mapping[str, np.ndarray]):
    """Named 1-D signals of equal length, sampled every ``dt`` seconds (None if unknown).

    Entries can be given lazily as zero-argument callables; they are computed on first access.
    Filtered versions of a signal (:meth:`derived`) are computed once for this object and the copies
    :meth:`with_columns` makes of it, as long as they hold the same array.

    ``starts``: the first sample of each run of consecutive samples (default: one run, ``(0,)``); filters with
    memory restart there (module doc).
    """

    def __init__(
        self,
        columns: Mapping[str, np.ndarray | Callable[[], np.ndarray]],
        dt: float | None,
        n: int,
        *,
        memo: dict | None = None,
        starts: Sequence[int] | None = None,
    ):
        self._cols = dict(columns)
        self.dt = dt
        self.n = int(n)
        self.starts = check_starts(starts, self.n)
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
        return Signals({**self._cols, **columns}, self.dt, self.n, memo=self._memo, starts=self.starts)

    def runs(self) -> list[tuple[int, int]]:
        """``[start, stop)`` of each run of consecutive samples (:attr:`starts`)."""
        return run_bounds(self.n, self.starts)

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


def check_starts(starts: Sequence[int] | None, n: int) -> tuple[int, ...]:
    """``starts`` as a tuple (``(0,)`` for None), checked: integers, strictly increasing, from 0, below ``n``."""
    if starts is None:
        return (0,)
    arr = np.asarray(starts).astype(np.int64)  # one pass for a log with thousands of runs
    if not arr.size or arr[0] != 0 or np.any(np.diff(arr) <= 0) or (n > 0 and arr[-1] >= n):
        raise IdentificationError(f"starts = {list(starts)[:8]}: expected strictly increasing sample indices "
                                  f"from 0, below the {n} samples")
    return tuple(arr.tolist())


def run_bounds(n: int, starts: Sequence[int] | None) -> list[tuple[int, int]]:
    """``[start, stop)`` of the runs of ``n`` samples that begin at ``starts`` (None: one run)."""
    if starts is None or len(starts) <= 1:
        return [(0, n)]
    edges = [*starts, n]
    return list(zip(edges[:-1], edges[1:], strict=False))


def per_run(f: Callable[..., np.ndarray], starts: Sequence[int] | None, *xs: np.ndarray) -> np.ndarray:
    """``f`` applied to the slices of ``xs`` of each run, concatenated (``f(*xs)`` itself for one run): the filter
    restarts at every start and reads no sample of another run."""
    bounds = run_bounds(len(xs[0]), starts)
    if len(bounds) == 1:
        return f(*xs)
    return np.concatenate([f(*(x[a:b] for x in xs)) for a, b in bounds])


def ticks(seconds: float, dt: float) -> int:
    """``seconds`` as a whole number of samples (at least 1)."""
    return max(1, int(round(seconds / dt)))


def _run_edges(n: int, starts: Sequence[int] | None) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``n`` samples, the index of its run's first and last sample (runs begin at ``starts``)."""
    bounds = np.asarray(run_bounds(n, starts), dtype=np.intp).reshape(-1, 2)
    lengths = bounds[:, 1] - bounds[:, 0]
    return np.repeat(bounds[:, 0], lengths), np.repeat(bounds[:, 1] - 1, lengths)


def delayed(x: np.ndarray, n: int, starts: Sequence[int] | None = None) -> np.ndarray:
    """``x`` delayed by ``n`` samples, the first value of each run repeated before its start."""
    if n <= 0:
        return x.copy()
    if starts is not None and len(starts) > 1:  # one gather for every run (a log with thousands of gaps)
        return x[np.maximum(np.arange(len(x)) - n, _run_edges(len(x), starts)[0])]
    if n >= len(x):
        return np.full_like(x, x[0])
    return np.concatenate([np.full(n, x[0]), x[:-n]])


def advanced(x: np.ndarray, n: int, starts: Sequence[int] | None = None) -> np.ndarray:
    """``x`` read ``n`` samples ahead, the last value of each run repeated past its end."""
    if starts is not None and len(starts) > 1:
        return x[np.minimum(np.arange(len(x)) + max(n, 0), _run_edges(len(x), starts)[1])]
    return np.concatenate([x[n:], np.full(min(n, len(x)), x[-1])])[:len(x)]


def lowpass_gain(time_constant: float, dt: float) -> float:
    """Gain ``a`` of ``y += a (x - y)``, the backward-Euler first-order lag of ``time_constant`` [s]."""
    return dt / (time_constant + dt)


def lowpass(x: np.ndarray, time_constant: float, dt: float, y0: float | None = None,
            starts: Sequence[int] | None = None) -> np.ndarray:
    """First-order lag ``y[k] = y[k-1] + a (x[k] - y[k-1])`` with ``y[-1] = y0`` (default ``x[0]``), restarted
    the same way at each run's start (``y0`` default: the run's first sample)."""
    from scipy.signal import lfilter  # here: importing scipy.signal takes about a second

    a = lowpass_gain(time_constant, dt)
    y, _ = lfilter([a], [1.0, -(1.0 - a)], x, zi=[(1.0 - a) * (float(x[0]) if y0 is None else y0)])
    if starts is not None and len(starts) > 1:
        # one filter over the whole log, then each later run's start corrected: the difference from the restarted
        # filter decays as (1 - a)^(samples into the run)
        first = _run_edges(len(x), starts)[0]
        k = np.flatnonzero(first > 0)
        s = first[k]
        restart = x[s] if y0 is None else y0
        y[k] -= (1.0 - a) ** (k - s + 1) * (y[s - 1] - restart)
    return y


def direction_latch(dq: np.ndarray, threshold: float, starts: Sequence[int] | None = None) -> np.ndarray:
    """Sign of the last velocity with ``|dq| > threshold`` [rad/s] (0 before any motion of the run)."""
    return sign_latch(dq, np.abs(dq) > threshold, starts)


def sign_latch(x: np.ndarray, flag: np.ndarray, starts: Sequence[int] | None = None) -> np.ndarray:
    """Sign of ``x`` at the last sample of the run where ``flag`` is True (0 before the run's first)."""
    idx = np.where(flag, np.arange(len(x)), -1)
    np.maximum.accumulate(idx, out=idx)
    out = np.sign(x[np.maximum(idx, 0)])
    first = _run_edges(len(x), starts)[0] if starts is not None and len(starts) > 1 else 0
    out[idx < first] = 0.0  # no flag yet in this run (the last one is in an earlier run, or none)
    return out


def run_onsets(flag: np.ndarray, starts: Sequence[int] | None = None) -> np.ndarray:
    """Index of the first sample of the run of ``True`` each sample belongs to (-1 before the first run;
    meaningful where ``flag`` is True); a run of ``True`` also begins at each of ``starts``."""
    idx = np.arange(len(flag))
    start = flag & ~np.concatenate([[False], flag[:-1]])
    if starts is not None and len(starts) > 1:
        start[list(starts)] = flag[list(starts)]
    out = np.where(start, idx, -1)
    np.maximum.accumulate(out, out=out)
    return out


def since_onset(x: np.ndarray, flag: np.ndarray, starts: Sequence[int] | None = None) -> np.ndarray:
    """``x - x[onset]`` where ``flag`` is True, ``onset`` the first sample of the run it belongs to (a run of
    ``True`` restarts at each of ``starts``); 0 elsewhere."""
    return np.where(flag, x - x[np.maximum(run_onsets(flag, starts), 0)], 0.0)


def hysteresis(x: np.ndarray, on: float, off: float, starts: Sequence[int] | None = None) -> np.ndarray:
    """A detector with hysteresis: True from the first ``x > on`` until ``x <= off`` (``off <= on``).

    One-step recursion ``s[k] = x[k] > (off if s[k-1] else on)``, written over the whole array: a sample
    is on if ``x > off`` and some sample of the same run of ``x > off`` reached ``on`` before it (or at it);
    the detector starts off at each of ``starts``.
    """
    if off > on:
        raise IdentificationError(f"hysteresis: off = {off!r} > on = {on!r}: expected off <= on")
    above_off = x > off
    idx = np.arange(len(x))
    last_on = np.maximum.accumulate(np.where(x > on, idx, -1))
    return above_off & (last_on >= run_onsets(above_off, starts)) & (last_on >= 0)


# -- helpers shared by several effects -----------------------------------------------------------------
SG_MIN = 5
"""[samples] Shortest Savitzky-Golay window of the acceleration (order 3): a window [s] of fewer samples is clamped
to it (:func:`~.excitation.shortest` offers no shape that would be)."""
V_EPS = (0.0, 0.005, 0.01, 0.02, 0.05)  # [rad/s] sign smoothing tried by the grids (0: plain sign)
INERTIA_LAGS = (0.0, 0.002, 0.005)  # [s] delays of the inertia term tried by the grids (that of the torque estimate)


def smooth_sign(x: np.ndarray, v: float) -> np.ndarray:
    """``tanh(x / v)``, or ``sign(x)`` for ``v <= 0``."""
    return np.sign(x) if v <= 0.0 else np.tanh(x / v)


def sign_of(s: Signals, name: str, v: float) -> np.ndarray:
    """:func:`smooth_sign` of signal ``name`` (read-only), computed once per ``v`` for ``s`` and its copies
    (:meth:`Signals.derived`): the friction terms read the same sign of ``dq`` in every fit of a diagnosis."""
    return s.derived(name, ("smooth_sign", v), lambda x: smooth_sign(x, v))


def bell_of(s: Signals, name: str, width: float) -> np.ndarray:
    """``exp(-(x / width)^2)`` of signal ``name`` (read-only), computed once per ``width`` like :func:`sign_of`."""
    return s.derived(name, ("bell", width), lambda x: np.exp(-((x / width) ** 2)))


def smooth_sign_scalar(x: float, v: float) -> float:
    """:func:`smooth_sign` of one sample."""
    return (x > 0) - (x < 0) if v <= 0.0 else math.tanh(x / v)


def command_lead(s: Signals) -> np.ndarray:
    """``q_des(t - 1 tick) - q(t)`` [rad]: the error the servo has to close at the start of the tick, up to
    the previous command (the integral of ``dq_des - dq``; this tick's command is not read). At a run's first
    sample, that sample's command."""
    return delayed(s["q_des"], 1, s.starts) - s["q"]


def sample_lead(x: Mapping[str, float], q_des_prev: float | None) -> float:
    """:func:`command_lead` of one sample: the last tick's command (this tick's on the first) minus ``q``."""
    return (x["q_des"] if q_des_prev is None else q_des_prev) - x["q"]


def acceleration(s: Signals, window: float) -> np.ndarray:
    """The acceleration [rad/s^2]: an estimate given with the data (``ddq_est``: an acceleration column of
    the log, or the controller's estimator on-line), else the centred SG second derivative of ``q`` over
    ``window`` [s] (order 3), fitted on each run (one-sided at its edges, module doc; a run shorter than the
    window takes ``ddq``, the data's own derivative of that run)."""
    if "ddq_est" in s:
        return s["ddq_est"]
    if window <= 0.0:
        return s["ddq"]
    dt = s.require_dt("acceleration")
    w = max(SG_MIN, int(round(window / dt)) | 1)
    if w > s.n:
        return s["ddq"]
    runs = s.runs()
    short = any(b - a < w for a, b in runs)
    ddq = s["ddq"] if short and "ddq" in s else None

    def second_derivative(q: np.ndarray) -> np.ndarray:
        out = savgol_centred_runs(q, np.asarray([r for r in runs if r[1] - r[0] >= w]), w, 3, dt, 2)
        for a, b in runs:
            if b - a >= w:
                continue
            if ddq is not None:
                out[a:b] = ddq[a:b]
                continue
            m = b - a if (b - a) % 2 else b - a - 1  # no ddq: the run's longest odd window, or no acceleration
            out[a:b] = savgol_centred(q[a:b], m, 3, dt, deriv=2) if m >= 5 else 0.0
        return out

    return s.derived("q", ("ddq", w, dt, s.starts), second_derivative)


def inertia(s: Signals, window: float, lag: float = 0.0) -> np.ndarray:
    """The acceleration of :func:`acceleration`, delayed by ``lag`` [s] like the torque estimate.

    The servo torque is the link torque plus the rotor's inertia torque ``J ddq``; when the torque column
    is an estimate that lags the encoders (an estimator's delay), only an equally delayed inertia term
    completes it into the (smooth) servo torque of that earlier instant. ``lag = 0``: no delay.
    """
    a = acceleration(s, window)
    if lag <= 0.0:
        return a
    return delayed(a, ticks(lag, s.require_dt("the lag of the inertia term")), s.starts)


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
