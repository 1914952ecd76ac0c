"""Result of a linear fit ``A x ~ b``: coefficients by name, the loss, quality metrics, solver report."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from servotau.actuator.loss import Loss
from servotau.errors import IdentificationError

from .metrics import overestimation_rate, residual_rms
from .regressors import Regressors


@dataclass(frozen=True)
class LinearFit:
    """Coefficients of one joint's linear model and how they were obtained.

    Attributes:
        coefficients: Coefficient by column name, in column order (e.g. ``k_tau`` [rad/(N m)]).
        loss: Loss that was minimised.
        rms: Residual RMS on the fitted samples [rad] (of the whole model, known offset included).
        overestimation_rate: Fraction of fitted samples where the model over-estimates |dq_err|.
        n_samples: Number of fitted samples.
        condition_number: Condition number of the regressor with columns normalised to unit RMS.
        solver: ``"lstsq"``, ``"newton"`` or ``"osqp"``.
        iterations: Solver iterations (1 for least squares).
        solve_time_s: Wall time of the solver call, validation excluded [s].
        status: Solver status, ``"solved"`` on success.
    """

    coefficients: Mapping[str, float]
    loss: Loss
    rms: float
    overestimation_rate: float
    n_samples: int
    condition_number: float
    solver: str
    iterations: int = 1
    solve_time_s: float = 0.0
    status: str = "solved"
    info: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "coefficients", {str(k): float(v) for k, v in self.coefficients.items()})
        object.__setattr__(self, "info", dict(self.info))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.coefficients)

    @property
    def x(self) -> np.ndarray:
        """Coefficients as an array in column order."""
        return np.array(list(self.coefficients.values()))

    def __getitem__(self, name: str) -> float:
        if name not in self.coefficients:
            raise IdentificationError(f"coefficient '{name}' not fitted: expected one of {list(self.coefficients)}")
        return self.coefficients[name]

    def predict(self, regressors: Regressors) -> np.ndarray:
        """Model output ``A x`` [rad] for regressors with the same column names."""
        if regressors.names != self.names:
            raise IdentificationError(
                f"regressor columns {list(regressors.names)}: expected {list(self.names)} (those of the fit)"
            )
        return regressors.matrix @ self.x


def make_fit(
    regressors: Regressors,
    dq_err: np.ndarray,
    x: np.ndarray,
    loss: Loss,
    condition: float,
    solver: str,
    offset: np.ndarray | None = None,
    **report,
) -> LinearFit:
    """Build a :class:`LinearFit` from a solution ``x``; metrics are of ``A x + offset`` against ``dq_err``."""
    model = regressors.matrix @ x
    if offset is not None:
        model = model + offset
    return LinearFit(
        coefficients=dict(zip(regressors.names, x.tolist(), strict=True)),
        loss=loss,
        rms=residual_rms(model, dq_err),
        overestimation_rate=overestimation_rate(model, dq_err),
        n_samples=regressors.n_samples,
        condition_number=condition,
        solver=solver,
        **report,
    )
