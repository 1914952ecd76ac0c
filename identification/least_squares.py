"""Least-squares identification, paper eq. 7: ``min_x ||A x - b||^2``."""

from __future__ import annotations

import time

import numpy as np

from servotau.actuator.loss import Loss

from .linear_fit import LinearFit, make_fit
from .problem import prepare_problem
from .regressors import Regressors
from .validation import MAX_CONDITION
from .validation import label as _label


def fit_least_squares(
    regressors: Regressors,
    dq_err: np.ndarray,
    *,
    offset: np.ndarray | None = None,
    min_samples: int | None = None,
    max_condition: float = MAX_CONDITION,
    what: str | None = None,
    constant: tuple[str, ...] = (),
) -> LinearFit:
    """Least-squares fit of ``A x + offset = dq_err``, ``A`` = ``regressors``.

    Args:
        regressors: Named columns of ``A``.
        dq_err: Position tracking error ``q_des - q`` [rad].
        offset: Known part of the model [rad] (e.g. ``k_tau * tau`` from a first stage), or None.
        min_samples: Fewest samples accepted (default 10 per coefficient).
        max_condition: Largest accepted condition number of the column-normalised ``A``.
        what: Name of the data set, prefixed to error messages.
        constant: Names of columns that may be constant (a fitted offset).

    Raises:
        IdentificationError: Bad data, see :func:`~servotau.identification.problem.prepare_problem`.
    """
    prob = prepare_problem(
        regressors,
        dq_err,
        offset=offset,
        min_samples=min_samples,
        max_condition=max_condition,
        what=_label(what, "least-squares fit"),
        constant=constant,
    )
    start = time.perf_counter()
    xs, *_ = np.linalg.lstsq(prob.a, prob.b, rcond=None)
    elapsed = time.perf_counter() - start
    return make_fit(
        regressors,
        prob.dq_err,
        prob.unscale(xs),
        Loss.least_squares(),
        prob.condition,
        "lstsq",
        offset=prob.offset,
        solve_time_s=elapsed,
    )
