"""The encoder's resolution read off the log, and the error floor it sets.

A quantised angle ``q = k res`` carries an error up to ``res / 2``, about ``res / sqrt(12)`` RMS, that is a
function of the true angle: on the holds it is a constant offset, the same wherever the joint returns to the same
angle. Any term that sets apart holding from moving, or a function of the position, can fit it. The diagnosis
therefore names no effect whose removed error (RMS, ``sqrt(E_base^2 - E_with^2)``) stays within that floor
(:func:`quantisation_floor`, :func:`within_resolution`; a probe's gain likewise, :func:`probes_within_resolution`):
below the encoder's resolution, the log cannot tell a physical effect from the encoder's rounding.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

__all__ = ["encoder_resolution", "error_floor", "probes_within_resolution", "quantisation_floor", "removed_error",
           "within_resolution"]

LATTICE_SHARE = 0.95  # of the steps between distinct angles that must be whole multiples of the smallest one
LATTICE_TOL = 1e-3  # [steps] how close to a whole multiple


def encoder_resolution(q: np.ndarray) -> float:
    """The step [rad] of the lattice the angles ``q`` sit on, or 0 when they sit on none (not quantised, or too
    finely for float64 to tell): the smallest step between distinct angles, when at least ``LATTICE_SHARE`` of
    the steps are whole multiples of it."""
    v = np.unique(np.asarray(q, dtype=float)[np.isfinite(q)])
    if v.size < 3:
        return 0.0
    steps = np.diff(v)
    scale = max(float(np.max(np.abs(v))), 1.0)
    steps = steps[steps > 1e-12 * scale]
    if steps.size < 2:
        return 0.0
    res = float(np.min(steps))
    k = steps / res
    if np.mean(np.abs(k - np.round(k)) < LATTICE_TOL) < LATTICE_SHARE:
        return 0.0
    return res


def quantisation_floor(resolution: float) -> float:
    """RMS [rad] of the rounding error of an encoder of ``resolution`` [rad]: ``resolution / sqrt(12)``."""
    return float(resolution) / np.sqrt(12.0)


def error_floor(ds, loss) -> float:
    """The encoder's rounding error [rad RMS] where it is part of the target of the dataset ``ds`` (``q_des - q``,
    with the least-squares ``loss``), else 0."""
    if not ds.actuator or loss.kind != "least_squares":
        return 0.0
    return quantisation_floor(ds.preprocessing.get("q", {}).get("resolution", 0.0))


def within_resolution(ds, ranking: list, e0: float, loss, min_gain: float) -> list:
    """``ranking`` (the diagnosis's candidates) with the effects that would be named but remove no more error than
    the encoder's rounding made untestable, saying so (least squares only: the errors are RMS); ``e0`` the base
    model's held-out error."""
    floor = error_floor(ds, loss)
    if floor <= 0:
        return ranking
    out = []
    for c in ranking:
        removed = removed_error(e0, c.heldout_error)
        if c.testable and c.heldout_gain >= min_gain and removed <= floor:
            c = replace(c, testable=False, reason=(
                f"cannot tell: removes {1e6 * removed:.3g} urad RMS, within the encoder's rounding error "
                f"({1e6 * floor:.3g} urad RMS, resolution {ds.preprocessing['q']['resolution']:.3g} rad)"))
        out.append(c)
    return out


def removed_error(e0: float, e1: float) -> float:
    """The error [RMS] a term removes when it takes the held-out error from ``e0`` to ``e1``."""
    return math.sqrt(max(e0 ** 2 - e1 ** 2, 0.0))


def probes_within_resolution(ds, probes: dict[str, float], e0: float, loss) -> tuple[dict[str, float], tuple[str, ...]]:
    """``probes`` with the gains that remove no more error than the encoder's rounding set to 0, and a sentence
    for each (see :func:`within_resolution`)."""
    floor = error_floor(ds, loss)
    if floor <= 0:
        return probes, ()
    out, notes = dict(probes), []
    for k, g in probes.items():
        removed = removed_error(e0, e0 * (1.0 - g)) if g > 0 else 0.0
        if 0 < removed <= floor:
            out[k] = 0.0
            if g >= 0.05:
                notes.append(f"cannot tell: the {k} probe removes {1e6 * removed:.3g} urad RMS ({100 * g:.0f} %), "
                             f"within the encoder's rounding error ({1e6 * floor:.3g} urad RMS)")
    return out, tuple(notes)
