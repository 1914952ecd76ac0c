"""The encoder's resolution read off the log, and the error floor it sets.

A quantised angle ``q = k res`` carries an error up to ``res / 2``, about ``res / sqrt(12)`` RMS, that is a
function of the true angle: on the holds it is a constant offset, the same wherever the joint returns to the same
angle. Any term that sets apart holding from moving, or a function of the position, can fit it. The diagnosis
therefore names no effect whose removed error (RMS, ``sqrt(E_base^2 - E_with^2)``) stays within that floor
(:func:`quantisation_floor`): below the encoder's resolution, the log cannot tell a physical effect from the
encoder's rounding.
"""

from __future__ import annotations

import numpy as np

__all__ = ["encoder_resolution", "quantisation_floor"]

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
