"""Regressor matrices with named columns for the actuator model (paper eq. 6-7).

Model of one joint::

    dq_err = q_des - q = k_tau * tau + k_v * dq [+ k_c * sign(dq)] [+ sum_e k_e * phi_e(...)]

Column names are the coefficient names: ``k_tau`` (tau [N m]), ``k_v`` (dq [rad/s]), ``k_c``
(sign(dq) [-]), and any extra term given by the caller.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from servotau.actuator.terms import K_C, K_TAU, K_V
from servotau.errors import IdentificationError

from .validation import as_samples, check_same_length


@dataclass(frozen=True, eq=False)
class Regressors:
    """The matrix ``A`` of ``A x = b``: one row per sample, one named column per coefficient.

    Attributes:
        names: Coefficient name of each column, e.g. ``("k_tau", "k_v")``.
        matrix: Array of shape ``(n_samples, len(names))``, finite, read-only.
    """

    names: tuple[str, ...]
    matrix: np.ndarray

    def __post_init__(self) -> None:
        names = tuple(self.names)
        if not names or len(set(names)) != len(names) or not all(isinstance(n, str) and n for n in names):
            raise IdentificationError(f"regressor names = {self.names!r}: expected distinct non-empty strings")
        matrix = np.array(self.matrix, dtype=np.float64)
        if matrix.ndim != 2 or matrix.shape[1] != len(names):
            raise IdentificationError(
                f"regressor matrix: shape {matrix.shape}: expected (n_samples, {len(names)}) for columns {list(names)}"
            )
        bad = ~np.isfinite(matrix)
        if bad.any():
            row, col = (int(i) for i in np.argwhere(bad)[0])
            raise IdentificationError(
                f"regressor column '{names[col]}': {int(bad[:, col].sum())} samples are NaN or inf "
                f"(first at index {row}): expected finite numbers only"
            )
        matrix.flags.writeable = False
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "matrix", matrix)

    @property
    def n_samples(self) -> int:
        return self.matrix.shape[0]

    def column(self, name: str) -> np.ndarray:
        """The column of coefficient ``name``."""
        if name not in self.names:
            raise IdentificationError(f"regressor column '{name}' not found: expected one of {list(self.names)}")
        return self.matrix[:, self.names.index(name)]

    def select(self, mask: np.ndarray) -> Regressors:
        """The rows where boolean ``mask`` is true."""
        return Regressors(self.names, self.matrix[mask])


def sign(x: np.ndarray) -> np.ndarray:
    """Plain sign: -1, 0 (exactly at zero) or +1; no smoothing."""
    return np.sign(x)


def linear_regressors(
    tau: np.ndarray,
    dq: np.ndarray,
    *,
    coulomb: bool = False,
    extra: Mapping[str, np.ndarray] | None = None,
) -> Regressors:
    """Regressor of eq. 7: columns ``k_tau`` = tau, ``k_v`` = dq, optionally ``k_c`` = sign(dq), then extras.

    Args:
        tau: Joint torque [N m].
        dq: Joint velocity [rad/s].
        coulomb: Add the Coulomb column sign(dq) (zero at dq == 0).
        extra: Additional columns by coefficient name, each a 1-D array of the same length.
    """
    inputs = {"tau": as_samples("tau", tau), "dq": as_samples("dq", dq)}
    for name, values in (extra or {}).items():
        if name in (K_TAU, K_V, K_C, "tau", "dq"):
            raise IdentificationError(f"extra regressor '{name}': expected a name other than {[K_TAU, K_V, K_C]}")
        inputs[name] = as_samples(f"extra regressor '{name}'", values)
    check_same_length(inputs)
    columns = {K_TAU: inputs.pop("tau"), K_V: inputs.pop("dq")}
    if coulomb:
        columns[K_C] = sign(columns[K_V])
    columns.update(inputs)
    return Regressors(tuple(columns), np.column_stack(list(columns.values())))
