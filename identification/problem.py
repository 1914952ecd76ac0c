"""A validated, scaled fitting problem ``A x + offset ~ dq_err`` shared by every solver.

``offset`` is a known part of the model (e.g. ``k_tau * tau`` fixed by the first stage of a two-stage
fit), so the fitted right-hand side is ``b = dq_err - offset``, while over-estimation keeps being
judged against ``dq_err`` itself (its sign, ``side``).

Solvers work on the scaled problem ``(A / col_scale) (x * col_scale / b_scale) ~ b / b_scale``, whose
columns and right-hand side have unit RMS, so that tolerances mean the same thing whatever the units
(k_tau ~ 1e-4 rad/(N m) next to k_v ~ 1e-2 rad/(rad/s)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from servotau.errors import IdentificationError

from .regressors import Regressors
from .validation import (
    MAX_CONDITION,
    MIN_SAMPLES_PER_PARAMETER,
    as_samples,
    check_condition,
    check_min_samples,
    check_same_length,
    column_scales,
    scaled_condition,
)


@dataclass(frozen=True, eq=False)
class Problem:
    """Scaled problem: ``a`` = A / col_scale, ``b`` = (dq_err - offset) / b_scale, ``gram`` = a^T a,
    ``side`` = sign(dq_err)."""

    regressors: Regressors
    dq_err: np.ndarray
    offset: np.ndarray | None
    side: np.ndarray
    a: np.ndarray
    b: np.ndarray
    col_scale: np.ndarray
    b_scale: float
    gram: np.ndarray
    condition: float

    def unscale(self, x_scaled: np.ndarray) -> np.ndarray:
        """Coefficients in physical units from a solution of the scaled problem."""
        return np.asarray(x_scaled) / self.col_scale * self.b_scale


def prepare_problem(
    regressors: Regressors,
    dq_err: np.ndarray,
    *,
    offset: np.ndarray | None = None,
    min_samples: int | None = None,
    max_condition: float = MAX_CONDITION,
    what: str = "fit",
    constant: tuple[str, ...] = (),
) -> Problem:
    """Validate ``regressors``, ``dq_err`` [rad] and the known model part ``offset`` [rad], and scale them.
    The columns named in ``constant`` may be constant (a fitted offset); any other constant column is refused.

    Raises:
        IdentificationError: NaN/inf, mismatched lengths, fewer than ``min_samples`` samples
            (default ``MIN_SAMPLES_PER_PARAMETER`` per column), a zero or constant column, or
            linearly dependent columns.
    """
    if not isinstance(regressors, Regressors):
        raise IdentificationError(f"regressors: got {type(regressors).__name__}: expected a Regressors")
    dq_err = as_samples("dq_err", dq_err)
    lengths = {"regressors": regressors.matrix, "dq_err": dq_err}
    if offset is not None:
        offset = as_samples("offset", offset)
        lengths["offset"] = offset
    n = check_same_length(lengths)
    b = dq_err if offset is None else dq_err - offset
    if min_samples is None:
        min_samples = MIN_SAMPLES_PER_PARAMETER * len(regressors.names)
    check_min_samples(n, min_samples, f"{what} (coefficients {list(regressors.names)})")
    col_scale = column_scales(regressors.names, regressors.matrix, what=f"{what}: regressor", constant=constant)
    a = regressors.matrix / col_scale
    gram = a.T @ a
    condition = scaled_condition(gram / n)
    check_condition(regressors.names, condition, max_condition, what=f"{what}: regressor")
    b_rms = float(np.sqrt(np.mean(b * b)))
    b_scale = b_rms if b_rms > 0.0 else 1.0
    return Problem(regressors, dq_err, offset, np.sign(dq_err), a, b / b_scale, col_scale, b_scale, gram, condition)
