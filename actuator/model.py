"""The identified actuator model of one joint (its file: :mod:`servotau.actuator.motor_file`).

Model of one joint: ``dq_err = k_tau tau + k_v dq [+ k_c sign(dq)] [+ sum_e coefficient_e phi_e]``, the extra
terms ``phi_e`` being effects of the registry (:mod:`servotau.actuator.effects`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from servotau.errors import IdentificationError

from .loss import Loss
from .online import OnlineModel, predict_batch
from .terms import K_C, K_TAU, K_V, ModelTerms


def _check(name: str, v: object, ok, expected: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not ok(v):
        raise IdentificationError(f"{name} = {v!r}: expected {expected}")
    return float(v)


@dataclass(frozen=True)
class FitMetrics:
    """Quality of a fit on its samples: ``rms`` [rad], ``overestimation_rate`` in [0, 1], ``n_samples``."""

    rms: float
    overestimation_rate: float
    n_samples: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "rms", _check("rms", self.rms, lambda v: v >= 0, "a finite number >= 0 [rad]"))
        object.__setattr__(
            self,
            "overestimation_rate",
            _check("overestimation_rate", self.overestimation_rate, lambda v: 0 <= v <= 1, "a number in [0, 1]"),
        )
        if isinstance(self.n_samples, bool) or not isinstance(self.n_samples, (int, np.integer)) or self.n_samples < 0:
            raise IdentificationError(f"n_samples = {self.n_samples!r}: expected an integer >= 0")
        object.__setattr__(self, "n_samples", int(self.n_samples))


@dataclass(frozen=True)
class EffectTerm:
    """An extra model term: its fitted ``coefficient`` and the ``shape`` parameters of its regressor."""

    coefficient: float
    shape: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "coefficient", _check("coefficient", self.coefficient, lambda v: True, "a finite number")
        )
        object.__setattr__(
            self,
            "shape",
            {str(k): _check(f"shape.{k}", v, lambda v: True, "a finite number") for k, v in self.shape.items()},
        )


@dataclass(frozen=True)
class MotorModel:
    """Identified actuator model of one joint.

    Attributes:
        k_tau: Torque gain [rad/(N m)], > 0.
        k_v: Velocity gain [rad/(rad/s)], >= 0.
        k_c: Coulomb gain [rad], >= 0, or None if not in the model.
        extra: Extra effect terms by name.
        loss: Loss of the fit.
        provenance: Where the data came from (log file, date, backend).
        metrics: Fit quality, or None for hand-written values.
    """

    k_tau: float
    k_v: float
    k_c: float | None = None
    extra: Mapping[str, EffectTerm] = field(default_factory=dict)
    loss: Loss = field(default_factory=Loss)
    provenance: str = ""
    metrics: FitMetrics | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "k_tau", _check("k_tau", self.k_tau, lambda v: v > 0, "a finite number > 0 [rad/(N m)]"))
        set_(self, "k_v", _check("k_v", self.k_v, lambda v: v >= 0, "a finite number >= 0 [rad/(rad/s)]"))
        if self.k_c is not None:
            set_(self, "k_c", _check("k_c", self.k_c, lambda v: v >= 0, "a finite number >= 0 [rad] or None"))
        for name, term in self.extra.items():
            if not isinstance(name, str) or not name or not isinstance(term, EffectTerm):
                raise IdentificationError(f"extra[{name!r}] = {term!r}: expected an EffectTerm under a non-empty name")
        set_(self, "extra", dict(self.extra))
        if not isinstance(self.loss, Loss):
            raise IdentificationError(f"loss = {self.loss!r}: expected a Loss")
        if not isinstance(self.provenance, str) or not self.provenance:
            raise IdentificationError(f"provenance = {self.provenance!r}: expected a non-empty string")
        if self.metrics is not None and not isinstance(self.metrics, FitMetrics):
            raise IdentificationError(f"metrics = {self.metrics!r}: expected FitMetrics or None")

    @classmethod
    def from_fit(
        cls,
        fit,
        provenance: str,
        extra_shapes: Mapping[str, Mapping[str, float]] | None = None,
    ) -> MotorModel:
        """Model from a fit of :mod:`servotau.identification` (a ``LinearFit``: ``coefficients``, ``loss``,
        ``rms``, ``overestimation_rate``, ``n_samples``; or a ``TwoStageFit``: the same with ``static`` and
        ``moving`` stages instead of ``loss``): ``k_tau``, ``k_v``, ``k_c`` by name, any other coefficient as an
        extra term with shape parameters from ``extra_shapes``. A two-stage fit records the moving stage's loss
        and notes both in ``provenance`` if they differ."""
        coefs = dict(fit.coefficients)
        missing = [k for k in (K_TAU, K_V) if k not in coefs]
        if missing:
            raise IdentificationError(f"fit coefficients {list(coefs)}: expected {missing} among them")
        if hasattr(fit, "moving"):  # a two-stage fit
            loss = fit.moving.loss
            if fit.static.loss != fit.moving.loss:
                provenance += f"; two-stage losses: static {fit.static.loss}, moving {fit.moving.loss}"
        else:
            loss = fit.loss
        shapes = extra_shapes or {}
        return cls(
            k_tau=coefs.pop(K_TAU),
            k_v=coefs.pop(K_V),
            k_c=coefs.pop(K_C, None),
            extra={name: EffectTerm(c, shapes.get(name, {})) for name, c in coefs.items()},
            loss=loss,
            provenance=provenance,
            metrics=FitMetrics(fit.rms, fit.overestimation_rate, fit.n_samples),
        )

    def predict(
        self,
        tau: np.ndarray,
        dq: np.ndarray,
        *,
        q: np.ndarray | None = None,
        q_des: np.ndarray | None = None,
        t: np.ndarray | None = None,
        ddq: np.ndarray | None = None,
        period: float | None = None,
    ) -> np.ndarray:
        """``k_tau tau + k_v dq [+ k_c sign(dq)] [+ extra terms]`` [rad] on arrays of samples.

        Extra terms are evaluated by the effect registry (:mod:`servotau.actuator.online`); the signals they
        need (``q``, ``q_des``, the time ``t`` or ``period``, the acceleration ``ddq``) must then be given. For
        one tick at a time with the state of effects with memory, use :meth:`online`.

        Raises:
            IdentificationError: An extra term is unknown or needs a signal that was not given.
        """
        if self.extra:
            return predict_batch(self, tau, dq, q=q, q_des=q_des, t=t, ddq=ddq, period=period)
        tau = np.asarray(tau, dtype=np.float64)
        dq = np.asarray(dq, dtype=np.float64)
        return self.k_tau * tau + self.k_v * dq + (self.k_c or 0.0) * np.sign(dq)

    def online(self, period: float) -> OnlineModel:
        """An :class:`~servotau.actuator.online.OnlineModel`: this model one control tick at a time
        (``step(tau, dq, q=..., q_des=..., t=..., ddq=...)``), effects with memory included."""
        return OnlineModel(self, period)

    def terms(self) -> ModelTerms:
        """The model as its evaluator reads it: ``k_c`` is the ``coulomb`` term with a plain sign
        (``v_eps = 0``), first, then the extra terms in order.

        Raises:
            IdentificationError: ``k_c`` and an extra term ``coulomb`` are both set, or a term is unknown.
        """
        coefs = {K_TAU: self.k_tau, K_V: self.k_v}
        terms = []
        if self.k_c is not None and "coulomb" in self.extra:
            raise IdentificationError("k_c and an extra term 'coulomb' are both set: expected one Coulomb term")
        if self.k_c is not None:
            terms.append(("coulomb", {"v_eps": 0.0}))
            coefs["coulomb"] = self.k_c
        for name, term in self.extra.items():
            terms.append((name, dict(term.shape)))
            coefs[name] = term.coefficient
        return ModelTerms((K_TAU, K_V), tuple(terms), coefs)


