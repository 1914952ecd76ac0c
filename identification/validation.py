"""Checks shared by every fit: finite 1-D samples of equal length, enough of them, excitation.

Every failure raises :class:`~servotau.errors.IdentificationError` naming the offending input and what
was expected; no fit ever runs silently on bad data.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from servotau.errors import IdentificationError

MIN_SAMPLES_PER_PARAMETER = 10
"""Default minimum number of samples per fitted coefficient."""

MAX_CONDITION = 1e6
"""Default largest condition number of the column-normalised regressor before a fit is refused."""


def label(what: str | None, fit: str) -> str:
    """Name of a fit in error messages: ``"<what>: <fit>"`` or just ``fit``."""
    return f"{what}: {fit}" if what else fit


def as_samples(name: str, values: object) -> np.ndarray:
    """Return ``values`` as a 1-D float64 array of finite numbers, or raise naming ``name``."""
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise IdentificationError(f"{name}: expected a 1-D array of floats, got {type(values).__name__}") from exc
    if arr.ndim != 1:
        raise IdentificationError(f"{name}: expected a 1-D array of samples, got shape {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        first = int(np.argmax(bad))
        raise IdentificationError(
            f"{name}: {int(bad.sum())} of {arr.size} samples are NaN or inf (first at index {first}, "
            f"= {arr[first]}): expected finite numbers only"
        )
    return arr


def check_same_length(arrays: Mapping[str, np.ndarray]) -> int:
    """Return the common length of ``arrays`` (name -> 1-D array), or raise listing every length."""
    lengths = {name: len(a) for name, a in arrays.items()}
    if len(set(lengths.values())) > 1:
        shown = ", ".join(f"{n}: {k}" for n, k in lengths.items())
        raise IdentificationError(f"mismatched lengths ({shown}): expected one sample of each per time step")
    return next(iter(lengths.values()))


def check_min_samples(n: int, minimum: int, what: str) -> None:
    """Raise if ``n`` samples are fewer than ``minimum`` (``what`` names the data set)."""
    if n < minimum:
        raise IdentificationError(f"{what}: {n} samples: expected at least {minimum}")


def column_scales(
    names: tuple[str, ...], matrix: np.ndarray, *, what: str = "regressor", constant: tuple[str, ...] = ()
) -> np.ndarray:
    """Return the RMS of every column; raise if a column is zero or does not vary (no excitation).

    A constant column (e.g. ``sign(dq)`` when the joint moved one way only, or a torque that never
    changed) cannot be told apart from an offset, so it is refused as unexcited, unless it is named in
    ``constant`` (the model's own offset column).
    """
    scales = np.sqrt(np.mean(matrix * matrix, axis=0))
    for j, name in enumerate(names):
        col = matrix[:, j]
        peak = float(np.max(np.abs(col)))
        if peak == 0.0:
            raise IdentificationError(
                f"{what} column '{name}' is all zero: no excitation, expected samples where it is nonzero"
            )
        if name not in constant and float(np.ptp(col)) <= 1e-12 * peak:
            raise IdentificationError(
                f"{what} column '{name}' is constant (= {col[0]:g}): no excitation, expected it to vary across samples"
            )
    return scales


def scaled_condition(gram_scaled: np.ndarray) -> float:
    """Condition number of a column-normalised regressor from its Gram matrix (accurate up to ~1e7)."""
    eig = np.linalg.eigvalsh(gram_scaled)
    if eig[0] <= 0.0:
        return math.inf
    return float(math.sqrt(eig[-1] / eig[0]))


def check_condition(names: tuple[str, ...], condition: float, max_condition: float, *, what: str = "regressor") -> None:
    """Raise if the columns ``names`` are (nearly) linearly dependent."""
    if not condition <= max_condition:
        raise IdentificationError(
            f"{what} columns {list(names)} are linearly dependent (condition number {condition:.3g} of the "
            f"column-normalised matrix): expected <= {max_condition:g}; excite each term independently"
        )
