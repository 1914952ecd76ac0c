"""A model as its evaluator reads it: the paper's linear coefficients and the effect terms, evaluated on arrays.

``dq_err = k_tau tau + k_v dq + sum_e c_e phi_e(signals; shape_e)``

Terms whose regressor reads ``u`` (:attr:`~servotau.actuator.registry.Effect.uses_model`) are evaluated on the
model's servo error without them (see :meth:`ModelTerms.context`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .registry import get_effect
from .signals import Signals

K_TAU = "k_tau"  # [rad/(N m)]
K_V = "k_v"  # [rad/(rad/s)]
K_C = "k_c"  # [rad]
OFFSET = "offset"  # [unit of the target] a constant term (general tables: a friction torque's mean off zero)


@dataclass(frozen=True, eq=False)
class ModelTerms:
    """Coefficients by name (``k_tau``, ``k_v`` if in ``linear``, effect names) and the effect terms with their
    shapes, in the order they are evaluated."""

    linear: tuple[str, ...]
    terms: tuple[tuple[str, Mapping[str, float]], ...]
    coefficients: Mapping[str, float]

    def __post_init__(self) -> None:
        for effect, _ in self.terms:
            get_effect(effect)

    def context(self, signals: Signals) -> dict[str, np.ndarray]:
        """The model-dependent signals [rad] that some regressors read: ``u_tau = k_tau tau``,
        ``u_v = k_v dq`` and ``u``, the model's prediction without the terms that read ``u`` (the paper's
        ``k_tau tau + k_v dq`` plus friction-like terms: the position error the servo works with)."""
        c = self.coefficients
        zero = np.zeros(signals.n)
        u_tau = c[K_TAU] * signals["tau"] if K_TAU in self.linear else zero
        u_v = c[K_V] * signals["dq"] if K_V in self.linear else zero
        u = u_tau + u_v
        if OFFSET in self.linear:
            u = u + c[OFFSET]
        for effect, shape in self.terms:
            eff = get_effect(effect)
            if not eff.uses_model:
                u = u + c[effect] * eff.evaluate(signals, shape)
        return {"u": u, "u_tau": u_tau, "u_v": u_v}

    def predict(self, signals: Signals) -> np.ndarray:
        """Model output [rad] on ``signals``."""
        ctx = self.context(signals)
        su = signals.with_columns(**ctx)
        out = ctx["u"].copy()
        for effect, shape in self.terms:
            eff = get_effect(effect)
            if eff.uses_model:
                out += self.coefficients[effect] * eff.evaluate(su, shape)
        return out
