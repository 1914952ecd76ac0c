"""Units of the workbench's error: they follow the role of the target column.

- an actuator log (``target = q_des - q``): the servo error [rad], shown in urad (RMS of the target
  under 20 mrad) or mrad;
- a table whose ``target`` role maps to a torque or friction column (its name holds ``tau``,
  ``torque``, ``friction``, ``effort`` or ``trq``): [N m], shown in mN m (RMS under 1 N m) or N m;
- anything else: the unit the user names (``--unit``), shown as is (``--unit rad`` or ``--unit "N m"``
  choose a prefix as above); without one the error is shown in the table's own unit, labelled ``?``.

Values in JSON stay in SI (or the table's unit); ``unit`` says how the text, HTML, plots and Rerun
scale and label them.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .data import TORQUE_COLUMN, Dataset

__all__ = ["Unit", "unit_for", "unit_of"]

_RAD_ALIASES = {"rad"}
_TORQUE_ALIASES = {"n m", "nm", "n.m", "n*m", "newton metre", "newton meter"}


@dataclass(frozen=True)
class Unit:
    """How an error is shown: ``scale * value`` in ``symbol``.

    Attributes:
        quantity: What the target is (``servo error``, ``torque``, or the target's column name).
        name: Short label of the target in plots (``dq_err`` for the servo error, else the column).
        si: The unit of the stored values (``rad``, ``N m``, the user's ``--unit``, or ``?``).
        symbol: The unit shown (``urad``, ``mrad``, ``mN m``, ``N m``, ...).
        scale: Shown value = ``scale`` * stored value.
    """

    quantity: str
    name: str
    si: str
    symbol: str
    scale: float

    def num(self, value: float) -> str:
        """``value`` (stored unit) scaled, as text: 2 decimals in a prefixed unit, else 4 significant digits."""
        v = self.scale * value
        return f"{v:.2f}" if self.scale != 1.0 else f"{v:.4g}"

    def show(self, value: float) -> str:
        """``value`` (stored unit) as text with its symbol."""
        return f"{self.num(value)} {self.symbol}"

    def to_dict(self) -> dict:
        return asdict(self)


def _rms(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=np.float64)
    return float(np.sqrt(np.mean(x * x))) if x.size else 0.0


def unit_for(si: str, rms: float, quantity: str, name: str) -> Unit:
    """The shown unit of a target in ``si`` whose RMS is ``rms`` (a prefix for rad and N m)."""
    key = si.strip().lower()
    if key in _RAD_ALIASES:
        if rms < 2e-2:
            return Unit(quantity, name, "rad", "urad", 1e6)
        return Unit(quantity, name, "rad", "mrad", 1e3)
    if key in _TORQUE_ALIASES:
        if rms < 1.0:
            return Unit(quantity, name, "N m", "mN m", 1e3)
        return Unit(quantity, name, "N m", "N m", 1.0)
    return Unit(quantity, name, si or "?", si or "?", 1.0)


def unit_of(ds: Dataset, override: str | None = None) -> Unit:
    """The unit of ``ds.target``: from its role (see the module doc), or ``override`` (``--unit``)."""
    rms = _rms(ds.target)
    column = ds.roles.get("target")
    if ds.actuator or column is None:
        quantity, name, si = "servo error", "dq_err", "rad"
    elif TORQUE_COLUMN.search(column):
        quantity, name, si = "torque", column, "N m"
    else:
        quantity, name, si = column, column, "?"
    if override:
        si = override
    return unit_for(si, rms, quantity, name)
