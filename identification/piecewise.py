"""Piecewise-linear fit of ``dq_err`` versus ``tau``, separately per velocity sign (paper section 3.2.2).

For each sign of ``dq`` the model is three lines joined at breakpoints ``tau_1 < tau_2`` [N m]::

    f(tau) = k_1 tau + q_1   if tau <= tau_1
             k_2 tau + q_2   if tau_1 <= tau <= tau_2
             k_3 tau + q_3   if tau >= tau_2

Algorithm, from initial breakpoints (default -0.5, +0.5 N m), for at most ``max_iterations``:

1. split the samples at the current breakpoints and fit each line to its segment by least squares,
   the middle slope ``k_2`` constrained to ``[k2_min, k2_max]`` (for one line, the bounded least-squares
   slope is the unbounded one clipped to the bounds, the intercept then refitted: exact);
2. move ``tau_1`` to the intersection of lines 1 and 2, ``tau_2`` to that of lines 2 and 3.

It has converged when neither breakpoint moved by more than ``tol``. The returned model (last lines,
breakpoints at their intersections) is continuous by construction. The problem is non-convex: a poor
initial guess can leave a segment empty or the intersections out of order, which raises
:class:`~servotau.errors.IdentificationError` rather than returning a meaningless model.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from servotau.errors import IdentificationError

from .metrics import residual_rms
from .validation import as_samples, check_min_samples, check_same_length

logger = logging.getLogger(__name__)

MIN_SEGMENT_SAMPLES = 3
"""Default fewest samples (with distinct torques) in each of the three segments."""


@dataclass(frozen=True)
class PiecewiseLinear:
    """Continuous three-segment line ``dq_err = f(tau)`` for one sign of the velocity.

    Attributes:
        slopes: ``(k_1, k_2, k_3)`` [rad/(N m)].
        intercepts: ``(q_1, q_2, q_3)`` [rad].
        breakpoints: ``(tau_1, tau_2)`` [N m], intersections of lines 1-2 and 2-3.
        converged: True if the breakpoints stopped moving within ``max_iterations``.
        iterations: Number of fit-and-update rounds done.
        breakpoint_history: Breakpoints before the first round and after every round [N m].
        rms: Residual RMS on the fitted samples [rad].
        n_samples: Number of fitted samples.
    """

    slopes: tuple[float, float, float]
    intercepts: tuple[float, float, float]
    breakpoints: tuple[float, float]
    converged: bool
    iterations: int
    breakpoint_history: tuple[tuple[float, float], ...]
    rms: float
    n_samples: int

    def __call__(self, tau: np.ndarray) -> np.ndarray:
        """Model output [rad] at torques ``tau`` [N m]."""
        return _evaluate(self.slopes, self.intercepts, self.breakpoints, np.asarray(tau, dtype=np.float64))


def _evaluate(k, q, t, tau: np.ndarray) -> np.ndarray:
    return np.where(tau < t[0], k[0] * tau + q[0], np.where(tau > t[1], k[2] * tau + q[2], k[1] * tau + q[1]))


@dataclass(frozen=True)
class PiecewiseFit:
    """Piecewise-linear model for ``dq > 0`` (``positive``) and ``dq < 0`` (``negative``)."""

    positive: PiecewiseLinear
    negative: PiecewiseLinear

    @property
    def converged(self) -> bool:
        return self.positive.converged and self.negative.converged

    def evaluate(self, tau: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """Model output [rad] at torques ``tau`` [N m] and velocities ``dq`` [rad/s].

        Uses ``positive`` where ``dq > 0``, ``negative`` where ``dq < 0`` and their mean where
        ``dq == 0`` (the sign, hence the model, is undefined there).
        """
        tau = np.asarray(tau, dtype=np.float64)
        dq = np.broadcast_to(np.asarray(dq, dtype=np.float64), tau.shape)
        fp, fn = self.positive(tau), self.negative(tau)
        return np.where(dq > 0.0, fp, np.where(dq < 0.0, fn, 0.5 * (fp + fn)))


def _line(tau: np.ndarray, y: np.ndarray, bounds: tuple[float, float] = (-math.inf, math.inf)) -> tuple[float, float]:
    """Least-squares ``y = k tau + q`` with ``k`` clipped to ``bounds`` (exact bounded solution)."""
    tm, ym = float(tau.mean()), float(y.mean())
    dt = tau - tm
    k = float(np.dot(dt, y - ym) / np.dot(dt, dt))
    k = min(max(k, bounds[0]), bounds[1])
    return k, ym - k * tm


def fit_piecewise_1d(
    tau: np.ndarray,
    dq_err: np.ndarray,
    *,
    breakpoints: tuple[float, float] = (-0.5, 0.5),
    k2_bounds: tuple[float, float] = (0.0, math.inf),
    max_iterations: int = 10,
    tol: float = 1e-9,
    min_segment_samples: int = MIN_SEGMENT_SAMPLES,
    strict: bool = False,
    what: str = "piecewise fit",
) -> PiecewiseLinear:
    """Fit a continuous three-segment line ``dq_err = f(tau)`` (one velocity sign).

    Args:
        tau: Joint torque [N m].
        dq_err: Position tracking error [rad].
        breakpoints: Initial ``(tau_1, tau_2)`` [N m], ``tau_1 < tau_2``.
        k2_bounds: ``(k2_min, k2_max)`` bounds of the middle slope [rad/(N m)].
        max_iterations: Most fit-and-update rounds.
        tol: Convergence threshold on the breakpoint change [N m].
        min_segment_samples: Fewest samples with distinct torques in every segment.
        strict: Raise if not converged after ``max_iterations`` (else log a warning).
        what: Name of the data set in messages.

    Raises:
        IdentificationError: Bad data or settings, an empty or degenerate segment, parallel lines, or
            breakpoints out of order; non-convergence if ``strict``.
    """
    tau = as_samples(f"{what}: tau", tau)
    y = as_samples(f"{what}: dq_err", dq_err)
    n = check_same_length({"tau": tau, "dq_err": y})
    t1, t2 = _check_settings(breakpoints, k2_bounds, max_iterations, tol, min_segment_samples)
    check_min_samples(n, 3 * min_segment_samples, what)
    history = [(t1, t2)]
    converged = False
    for it in range(1, max_iterations + 1):
        masks = (tau < t1, (tau >= t1) & (tau <= t2), tau > t2)
        for i, (mask, name) in enumerate(zip(masks, _segment_names(t1, t2), strict=True)):
            n_distinct = np.unique(tau[mask]).size
            if n_distinct < min_segment_samples:
                raise IdentificationError(
                    f"{what}: iteration {it}: segment {i + 1} ({name}) has {n_distinct} distinct torques: expected "
                    f"at least {min_segment_samples}; move the initial breakpoints {breakpoints} inside the data"
                )
        (k1, q1), (k2, q2), (k3, q3) = (
            _line(tau[masks[0]], y[masks[0]]),
            _line(tau[masks[1]], y[masks[1]], k2_bounds),
            _line(tau[masks[2]], y[masks[2]]),
        )
        if k1 == k2 or k3 == k2:
            raise IdentificationError(
                f"{what}: iteration {it}: the middle line is parallel to an outer one (slopes {k1:g}, {k2:g}, "
                f"{k3:g} rad/(N m)): expected intersecting lines; adjust k2_bounds {k2_bounds}"
            )
        new1, new2 = (q2 - q1) / (k1 - k2), (q3 - q2) / (k2 - k3)
        if not new1 < new2:
            raise IdentificationError(
                f"{what}: iteration {it}: breakpoints out of order (tau_1 = {new1:g} >= tau_2 = {new2:g} N m): "
                f"expected tau_1 < tau_2; try other initial breakpoints than {breakpoints} or tighter k2_bounds"
            )
        history.append((new1, new2))
        moved = max(abs(new1 - t1), abs(new2 - t2))
        t1, t2 = new1, new2
        if moved <= tol:
            converged = True
            break
    if not converged:
        msg = f"{what}: breakpoints still moving after max_iterations = {max_iterations} (last {history[-1]} N m)"
        if strict:
            raise IdentificationError(msg + ": expected convergence")
        logger.warning(msg)
    k, q = (k1, k2, k3), (q1, q2, q3)
    rms = residual_rms(_evaluate(k, q, (t1, t2), tau), y)
    return PiecewiseLinear(k, q, (t1, t2), converged, it, tuple(history), rms, n)


def fit_piecewise(
    tau: np.ndarray,
    dq: np.ndarray,
    dq_err: np.ndarray,
    **kwargs,
) -> PiecewiseFit:
    """Fit :func:`fit_piecewise_1d` separately to the samples with ``dq > 0`` and ``dq < 0``.

    Samples with ``dq == 0`` exactly belong to neither model and are left out. ``kwargs`` (breakpoints,
    k2_bounds, max_iterations, tol, min_segment_samples, strict) apply to both signs.
    """
    tau = as_samples("tau", tau)
    dq = as_samples("dq", dq)
    dq_err = as_samples("dq_err", dq_err)
    check_same_length({"tau": tau, "dq": dq, "dq_err": dq_err})
    fits = {}
    for name, mask in (("positive", dq > 0.0), ("negative", dq < 0.0)):
        if not mask.any():
            raise IdentificationError(
                f"dq: no sample with dq {'>' if name == 'positive' else '<'} 0: expected "
                "motion in both directions (one model per velocity sign)"
            )
        fits[name] = fit_piecewise_1d(tau[mask], dq_err[mask], what=f"piecewise fit (dq {name[:3]})", **kwargs)
    return PiecewiseFit(**fits)


def _segment_names(t1: float, t2: float) -> tuple[str, str, str]:
    return (f"tau < {t1:g} N m", f"{t1:g} <= tau <= {t2:g} N m", f"tau > {t2:g} N m")


def _check_settings(breakpoints, k2_bounds, max_iterations, tol, min_segment_samples) -> tuple[float, float]:
    try:
        t1, t2 = (float(b) for b in breakpoints)
    except (TypeError, ValueError) as exc:
        raise IdentificationError(f"breakpoints = {breakpoints!r}: expected two numbers [N m]") from exc
    if not (math.isfinite(t1) and math.isfinite(t2) and t1 < t2):
        raise IdentificationError(f"breakpoints = {breakpoints!r}: expected finite tau_1 < tau_2 [N m]")
    try:
        lo, hi = (float(b) for b in k2_bounds)
    except (TypeError, ValueError) as exc:
        raise IdentificationError(f"k2_bounds = {k2_bounds!r}: expected (k2_min, k2_max) [rad/(N m)]") from exc
    if math.isnan(lo) or math.isnan(hi) or lo > hi or lo == math.inf or hi == -math.inf:
        raise IdentificationError(f"k2_bounds = {k2_bounds!r}: expected k2_min <= k2_max [rad/(N m)]")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, int) or max_iterations < 1:
        raise IdentificationError(f"max_iterations = {max_iterations!r}: expected an integer >= 1")
    if not (isinstance(tol, (int, float)) and math.isfinite(tol) and tol >= 0.0):
        raise IdentificationError(f"tol = {tol!r}: expected a finite number >= 0 [N m]")
    if isinstance(min_segment_samples, bool) or not isinstance(min_segment_samples, int) or min_segment_samples < 2:
        raise IdentificationError(f"min_segment_samples = {min_segment_samples!r}: expected an integer >= 2")
    return t1, t2
