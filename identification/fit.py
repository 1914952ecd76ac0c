"""One entry point for a linear fit with a chosen :class:`Loss` (least squares or asymmetric)."""

from __future__ import annotations

import numpy as np

from servotau.actuator.loss import Loss

from .asymmetric import fit_asymmetric
from .least_squares import fit_least_squares
from .linear_fit import LinearFit
from .regressors import Regressors, linear_regressors


def fit_with_loss(
    regressors: Regressors,
    dq_err: np.ndarray,
    loss: Loss,
    *,
    offset: np.ndarray | None = None,
    solver: str = "newton",
    **kwargs,
) -> LinearFit:
    """Fit ``A x + offset ~ dq_err`` [rad] minimising ``loss``.

    Args:
        regressors: Named columns of ``A``.
        dq_err: Position tracking error ``q_des - q`` [rad].
        loss: :class:`Loss` to minimise.
        offset: Known part of the model [rad], or None.
        solver: Asymmetric solver, ``"newton"`` or ``"osqp"`` (ignored for least squares).
        **kwargs: ``min_samples``, ``max_condition``, ``constant`` (columns that may be constant: a fitted offset)
            and solver options.
    """
    if loss.kind == "least_squares":
        return fit_least_squares(regressors, dq_err, offset=offset, **kwargs)
    return fit_asymmetric(regressors, dq_err, loss.w, offset=offset, solver=solver, **kwargs)


def fit_linear_model(
    tau: np.ndarray,
    dq: np.ndarray,
    dq_err: np.ndarray,
    *,
    coulomb: bool = False,
    loss: Loss | None = None,
    solver: str = "newton",
    **kwargs,
) -> LinearFit:
    """Eq. 6 on raw samples: ``dq_err = k_tau tau + k_v dq [+ k_c sign(dq)]`` in one call.

    Args:
        tau: Joint torque [N m].
        dq: Joint velocity [rad/s].
        dq_err: Position tracking error ``q_des - q`` [rad].
        coulomb: Also fit the Coulomb term ``k_c`` [rad].
        loss: Loss to minimise (default least squares, eq. 7).
        solver: Asymmetric solver, ``"newton"`` or ``"osqp"``.
        **kwargs: ``min_samples``, ``max_condition`` and solver options.
    """
    regressors = linear_regressors(tau, dq, coulomb=coulomb)
    return fit_with_loss(regressors, dq_err, loss or Loss.least_squares(), solver=solver, **kwargs)
