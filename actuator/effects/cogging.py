"""``cogging``: torque ripple periodic in the joint angle (motor cogging, gear tooth mesh).

``phi = sin(2 pi q / period + phase)``; fitted as a sine and a cosine of unknown phase, folded into one
coefficient and the ``phase``. On-line: ``q``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..excitation import POSITION_BINS, Excitation
from ..registry import Effect
from ..signals import Signals

ORDER = 90
PERIODS = (0.01, 0.32)  # [rad] the shortest and longest ripple periods tried
COARSE = tuple({"period": p} for p in np.geomspace(*PERIODS, 11).round(4).tolist())  # [rad] without positions
SAMPLES_PER_PERIOD = 4  # positions sampled per ripple period (at most the largest gap apart) that resolve a ripple
DENSE_PERIODS = 2  # ripple periods over a densely sampled stretch that resolve a ripple despite gaps elsewhere
DRIFT = 0.125  # [periods] the largest phase drift, at either end of the sweep, of a ripple half a grid step off
MIN_STEP = 0.05  # the finest relative step: short periods over a long sweep drift more (their cost grows as 1/step)


def grid(s: Signals) -> tuple[dict[str, float], ...]:
    """``COARSE`` and periods spaced so that a ripple between two of them drifts at most ``DRIFT`` of a period
    against the nearer one over the log's position sweep (a step of ``4 DRIFT period / span``, at least
    ``MIN_STEP``): a 41 % step alone leaves a ripple of 10 periods or more in the sweep unfitted. The sweep's span
    [rad] is the range of ``q``; without it, ``COARSE``."""
    q = s.get("q")
    span = float(np.ptp(q)) if q is not None and q.size > 1 else 0.0
    if not span > 0:
        return COARSE
    periods, p = {g["period"] for g in COARSE}, PERIODS[0]
    while p < PERIODS[1]:
        periods.add(round(p, 6))
        p *= 1.0 + max(4.0 * DRIFT * p / span, MIN_STEP)
    return tuple({"period": v} for v in sorted(periods))


GRID = grid


def cogging(s: Signals, period: float, phase: float = 0.0) -> np.ndarray:
    return np.sin(2.0 * math.pi * s["q"] / period + phase)


def columns(s: Signals, period: float, phase: float = 0.0) -> np.ndarray:
    """Sine and cosine of the ripple (``phase``, which they fit, is ignored: the grid is a function, so a folded
    shape keeps it)."""
    x = 2.0 * math.pi * s["q"] / period
    return np.column_stack([np.sin(x), np.cos(x)])


def fold(c: np.ndarray, shape: Mapping[str, float]) -> tuple[float, dict[str, float]]:
    # a sin(x) + b cos(x) = r sin(x + phase)
    return float(math.hypot(c[0], c[1])), {**shape, "phase": float(math.atan2(c[1], c[0]))}


def scalar(x: Mapping[str, float], period: float, phase: float = 0.0) -> float:
    return math.sin(2.0 * math.pi * x["q"] / period + phase)


def needs(e: Excitation) -> str | None:
    """A sweep of the position over several ripple periods, sampled densely enough for a period of the grid: no
    gap in the positions sampled longer than a quarter of the grid's longest period, or a stretch sampled densely
    over ``DENSE_PERIODS`` periods of a ripple it resolves (a ripple of known period is fitted from that stretch;
    the sparse rest only adds samples)."""
    if e.position_range is None:
        return "no position column"
    span = e.position_range[1] - e.position_range[0]
    if span < 0.05:
        return f"position range {span:.3g} rad: expected >= 0.05 rad, a sweep over several ripple periods"
    longest = PERIODS[1]
    if e.position_gap is None or e.position_gap * SAMPLES_PER_PERIOD <= longest:
        return None
    # the shortest period with SAMPLES_PER_PERIOD bins (a bin is 1 % of the 1-99 % quantile range, at most of span)
    shortest = max(PERIODS[0], SAMPLES_PER_PERIOD * span / POSITION_BINS)
    if shortest <= longest and e.position_dense is not None and e.position_dense >= DENSE_PERIODS * shortest:
        return None
    return (f"cannot tell: the positions sampled leave gaps of {e.position_gap:.3g} rad: a ripple needs "
            f">= {SAMPLES_PER_PERIOD} positions per period, so periods >= "
            f"{SAMPLES_PER_PERIOD * e.position_gap:.3g} rad (the grid's longest is {longest:g} rad), and no stretch "
            f"is sampled densely over {DENSE_PERIODS} periods of {shortest:.3g} rad (the longest: "
            f"{e.position_dense or 0.0:.3g} rad)")


EFFECT = Effect(
    "cogging", cogging, GRID, ("q",),
    signature="residual against position: a ripple of fixed period",
    family="position",
    description="torque ripple periodic in the joint angle (motor cogging, gear tooth mesh)",
    needs=needs,
    fit_columns=columns,
    fold=fold,
    scalar=scalar,
    online_signals="q",
    phi_unit="1",
)
