"""Two-stage identification, paper section 3.3.1.

1. Static samples (``|dq| < dq_static``) identify ``k_tau`` from ``dq_err = k_tau tau``.
2. Moving samples (``|dq| >= dq_moving``), with ``k_tau`` fixed, identify ``k_v`` (and ``k_c``) from
   ``dq_err - k_tau tau = k_v dq [+ k_c sign(dq)]``.

Since ``k_v`` is one or two orders of magnitude larger than ``k_tau`` (in rad/(rad/s) versus rad/(N m)),
friction dominates ``dq_err`` as soon as the joint moves, which makes ``k_tau`` poorly conditioned in a
joint fit; the static stage avoids that.

Default threshold ``dq_static = 0.01`` rad/s: the first stage ignores ``k_v dq``, so its error is at most
``k_v * dq_static``, about 1e-4 rad for HRP-2 leg joints (k_v ~ 0.006-0.013 rad/(rad/s)), against
``k_tau tau`` of 1e-3 to 1e-2 rad at the tens of N m the static experiments apply; its sign follows the
velocity noise, so it mostly averages out. The Coulomb term is never fitted in the static stage, since
``sign(dq)`` of a near-zero velocity is noise. ``dq_moving`` (default = ``dq_static``) can be raised to
drop the transition band from the second stage.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from servotau.actuator.loss import Loss
from servotau.errors import IdentificationError

from .fit import fit_with_loss
from .linear_fit import LinearFit
from .metrics import overestimation_rate, residual_rms
from .regressors import K_C, K_TAU, K_V, Regressors, sign
from .validation import as_samples, check_same_length

DQ_STATIC = 0.01  # [rad/s]


@dataclass(frozen=True)
class TwoStageFit:
    """Both stages and the combined model ``dq_err = k_tau tau + k_v dq [+ k_c sign(dq)]``.

    Attributes:
        static: Stage 1 fit (``k_tau``) on the static samples.
        moving: Stage 2 fit (``k_v`` [, ``k_c``]) on the moving samples, ``k_tau`` fixed; its metrics
            are those of the whole model on those samples.
        dq_static: Static threshold [rad/s].
        dq_moving: Moving threshold [rad/s].
        rms: Residual RMS of the combined model on all samples [rad].
        overestimation_rate: Over-estimation rate of the combined model on all samples.
        n_samples: Number of samples given (static + moving + ignored transition band).
    """

    static: LinearFit
    moving: LinearFit
    dq_static: float
    dq_moving: float
    rms: float
    overestimation_rate: float
    n_samples: int

    @property
    def coefficients(self) -> dict[str, float]:
        """``k_tau`` [rad/(N m)], ``k_v`` [rad/(rad/s)] and, if fitted, ``k_c`` [rad]."""
        return {**self.static.coefficients, **self.moving.coefficients}

    def predict(self, tau: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """Combined model output [rad] for torques ``tau`` [N m] and velocities ``dq`` [rad/s]."""
        return _predict(self.coefficients, np.asarray(tau, dtype=np.float64), np.asarray(dq, dtype=np.float64))


def _predict(c: dict[str, float], tau: np.ndarray, dq: np.ndarray) -> np.ndarray:
    return c[K_TAU] * tau + c[K_V] * dq + c.get(K_C, 0.0) * sign(dq)


def fit_two_stage(
    tau: np.ndarray,
    dq: np.ndarray,
    dq_err: np.ndarray,
    *,
    dq_static: float = DQ_STATIC,
    dq_moving: float | None = None,
    coulomb: bool = False,
    static_loss: Loss | None = None,
    moving_loss: Loss | None = None,
    solver: str = "newton",
    **kwargs,
) -> TwoStageFit:
    """Identify ``k_tau`` on static samples, then ``k_v`` (and ``k_c``) on moving samples.

    Args:
        tau: Joint torque [N m].
        dq: Joint velocity [rad/s].
        dq_err: Position tracking error ``q_des - q`` [rad].
        dq_static: Samples with ``|dq| < dq_static`` [rad/s] are static.
        dq_moving: Samples with ``|dq| >= dq_moving`` [rad/s] are moving (default ``dq_static``).
        coulomb: Also fit ``k_c`` in the second stage.
        static_loss: Loss of stage 1 (default least squares).
        moving_loss: Loss of stage 2 (default least squares).
        solver: Asymmetric solver, ``"newton"`` or ``"osqp"``.
        **kwargs: ``min_samples``, ``max_condition``, passed to both stages.

    Raises:
        IdentificationError: Bad data or thresholds, or too few static or moving samples.
    """
    tau = as_samples("tau", tau)
    dq = as_samples("dq", dq)
    dq_err = as_samples("dq_err", dq_err)
    n = check_same_length({"tau": tau, "dq": dq, "dq_err": dq_err})
    dq_moving = dq_static if dq_moving is None else dq_moving
    if not (np.isfinite(dq_static) and dq_static > 0.0):
        raise IdentificationError(f"dq_static = {dq_static!r}: expected a finite number > 0 [rad/s]")
    if not (np.isfinite(dq_moving) and dq_moving >= dq_static):
        raise IdentificationError(f"dq_moving = {dq_moving!r}: expected a finite number >= dq_static [rad/s]")
    static_loss = static_loss or Loss.least_squares()
    moving_loss = moving_loss or Loss.least_squares()

    still = np.abs(dq) < dq_static
    static = fit_with_loss(
        Regressors((K_TAU,), tau[still, None]),
        dq_err[still],
        static_loss,
        solver=solver,
        what=f"stage 1 (static, |dq| < {dq_static:g} rad/s)",
        **kwargs,
    )
    k_tau = static[K_TAU]

    moves = np.abs(dq) >= dq_moving
    columns = [dq[moves]] + ([sign(dq[moves])] if coulomb else [])
    names = (K_V, K_C) if coulomb else (K_V,)
    moving = fit_with_loss(
        Regressors(names, np.column_stack(columns)),
        dq_err[moves],
        moving_loss,
        offset=k_tau * tau[moves],
        solver=solver,
        what=f"stage 2 (moving, |dq| >= {dq_moving:g} rad/s)",
        **kwargs,
    )

    model = _predict({**static.coefficients, **moving.coefficients}, tau, dq)
    return TwoStageFit(
        static,
        moving,
        float(dq_static),
        float(dq_moving),
        residual_rms(model, dq_err),
        overestimation_rate(model, dq_err),
        n,
    )
