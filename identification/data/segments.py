"""Contiguous segments of a log and the shift of one signal against the others.

Both identification paths cut a log into segments before filtering (a centred filter must not run across a
gap) and pair ``dq_err[k]`` with a signal of another row (the torque of period ``k`` is the sensors' reading of
frame ``k + 1``). Their rules differ and each is kept as a parameter:

- :func:`segments`: the paper's pipeline cuts where ``seq`` does not step by one or the time step differs from
  the period (``max_gap=None``); the workbench cuts at invalid rows (NaN) and where the time step exceeds
  ``max_gap = 1.5`` periods.
- :func:`shift`: the pipeline fills past the end with NaN (those rows are dropped); the workbench holds the edge
  values (``fill="hold"``: every row is kept).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from servotau.errors import IdentificationError

PERIOD_RTOL = 1e-3  # relative tolerance of a regular tick (max_gap=None)


def segments(t: np.ndarray | None = None, period: float | None = None, *, seq: np.ndarray | None = None,
             valid: np.ndarray | None = None, max_gap: float | None = None) -> list[tuple[int, int]]:
    """``[start, stop)`` row ranges of consecutive samples.

    A range ends where the next row is not ``valid`` (invalid rows belong to no range), where ``seq`` does not
    step by one, or where the time step breaks the rule: with ``max_gap=None``, a step that is not the ``period``
    (relative tolerance ``PERIOD_RTOL``); with ``max_gap``, a step longer than ``max_gap * period``. Without ``t``
    or ``period`` there is no time rule.

    Args:
        t: Time [s] of every row.
        period: Sampling period [s].
        seq: Tick counter of every row (a servotau log's ``seq``).
        valid: Rows that may belong to a range (default: all).
        max_gap: Longest time step inside a range, in periods (None: exactly one period).
    """
    arrays = [np.asarray(a) for a in (t, seq, valid) if a is not None]
    if not arrays:
        raise IdentificationError("segments: expected at least one of t, seq, valid")
    n = len(arrays[0])
    if any(len(a) != n for a in arrays):
        raise IdentificationError(f"segments: t, seq, valid of lengths {[len(a) for a in arrays]}: expected equal")
    if n == 0:
        return []
    cut = np.zeros(n - 1, dtype=bool)  # cut[i]: a range ends between rows i and i + 1
    if seq is not None:
        cut |= np.diff(seq) != 1
    if t is not None and period is not None:
        step = np.diff(t)
        cut |= (step > max_gap * period) if max_gap is not None else ~np.isclose(step, period, rtol=PERIOD_RTOL,
                                                                                  atol=1e-9)
    ok = np.ones(n, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    starts = np.flatnonzero(ok & np.concatenate([[True], cut | ~ok[:-1]]))
    stops = np.flatnonzero(ok & np.concatenate([cut | ~ok[1:], [True]])) + 1
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def shift(x: np.ndarray, k: int, fill: Literal["nan", "hold"] = "nan") -> np.ndarray:
    """``out[i] = x[i + k]`` along the first axis (``k > 0`` advances, ``k < 0`` delays); the ``|k|`` rows with
    no source are NaN (``fill="nan"``) or the edge value (``fill="hold"``)."""
    if fill not in ("nan", "hold"):
        raise IdentificationError(f"shift: fill = {fill!r}: expected 'nan' or 'hold'")
    if k == 0:
        return x.copy()
    if fill == "hold":
        m = min(abs(k), len(x))  # a shift past the whole array holds the edge value everywhere
        if k > 0:
            return np.concatenate([x[m:], np.repeat(x[-1:], m, axis=0)])
        return np.concatenate([np.repeat(x[:1], m, axis=0), x[:len(x) - m]])
    out = np.full_like(x, np.nan)
    if k > 0:
        out[:-k] = x[k:]
    else:
        out[-k:] = x[:k]
    return out
