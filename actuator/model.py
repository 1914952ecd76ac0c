"""The identified actuator model of one joint (its file: :mod:`servotau.actuator.motor_file`).

Model of one joint: ``y = [k_tau tau +] k_v dq [+ k_c sign(dq)] [+ offset] [+ sum_e coefficient_e phi_e]``,
the extra terms ``phi_e`` being effects of the registry (:mod:`servotau.actuator.effects`). ``y`` is the
model's ``target`` in ``unit``: by default the servo error ``dq_err = q_des - q`` [rad] (the controller's and
the torque estimator's model); a model of another table (a friction torque [N m], a user unit) says so.
A term that is not in the model is None, never 0: a model without ``k_tau`` does not read the torque.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from servotau.errors import IdentificationError

from .loss import Loss
from .online import OnlineModel, predict_batch
from .terms import K_C, K_TAU, K_V, OFFSET, ModelTerms

SERVO_ERROR = "servo error"  # the default target: dq_err = q_des - q
SERVO_UNIT = "rad"


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

    Attributes (``U`` is the target's ``unit``, rad for the servo error):
        k_tau: Torque gain [U/(N m)], or None if the model has no torque term; > 0 for a servo error.
        k_v: Velocity gain [U/(rad/s)]; >= 0 for a servo error.
        k_c: Coulomb gain [U], >= 0, or None if not in the model.
        extra: Extra effect terms by name.
        loss: Loss of the fit.
        provenance: Where the data came from (log file, date, backend).
        metrics: Fit quality, or None for hand-written values.
        offset: Constant term [U], or None if not in the model.
        target: What the model predicts: ``"servo error"`` (``q_des - q``), ``"torque"`` (a torque or friction
            column), or the name of a user's target column.
        unit: The target's unit ``U``: ``"rad"``, ``"N m"``, or the user's (``"?"`` if not known).
    """

    k_tau: float | None
    k_v: float
    k_c: float | None = None
    extra: Mapping[str, EffectTerm] = field(default_factory=dict)
    loss: Loss = field(default_factory=Loss)
    provenance: str = ""
    metrics: FitMetrics | None = None
    offset: float | None = None
    target: str = SERVO_ERROR
    unit: str = SERVO_UNIT

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name in ("target", "unit"):
            v = getattr(self, name)
            if not isinstance(v, str) or not v.strip():
                raise IdentificationError(f"{name} = {v!r}: expected a non-empty string")
        u = self.unit
        if self.is_servo_error:  # the controller's model: the paper's signs
            kt, kv = (lambda v: v > 0, f"> 0 [{u}/(N m)]"), (lambda v: v >= 0, f">= 0 [{u}/(rad/s)]")
        else:
            kt, kv = (lambda v: True, f"[{u}/(N m)]"), (lambda v: True, f"[{u}/(rad/s)]")
        if self.k_tau is not None:
            set_(self, "k_tau", _check("k_tau", self.k_tau, kt[0], f"a finite number {kt[1]} or None"))
        set_(self, "k_v", _check("k_v", self.k_v, kv[0], f"a finite number {kv[1]}"))
        if self.k_c is not None:
            set_(self, "k_c", _check("k_c", self.k_c, lambda v: v >= 0, f"a finite number >= 0 [{u}] or None"))
        if self.offset is not None:
            set_(self, "offset", _check("offset", self.offset, lambda v: True, f"a finite number [{u}] or None"))
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

    @property
    def is_servo_error(self) -> bool:
        """The model predicts the servo error ``q_des - q`` [rad] (the default)."""
        return self.target == SERVO_ERROR and self.unit == SERVO_UNIT

    def servo_issue(self) -> tuple[str, str] | None:
        """Why the controller or the torque estimator cannot use this model, as ``(key, "<value>: expected
        ...")``; None if they can (a servo-error model with ``k_tau`` and no offset)."""
        if not self.is_servo_error:
            return "target", (f"= {self.target!r} [{self.unit}]: expected a model of the servo error "
                              f"'{SERVO_ERROR}' [{SERVO_UNIT}]")
        if self.k_tau is None:
            return K_TAU, "missing: expected the torque gain k_tau > 0 [rad/(N m)] (a model fitted with a torque)"
        if self.offset is not None:
            return OFFSET, (f"= {self.offset!r}: expected no constant term (the feedforward and the torque "
                            "prediction have none; refit with --offset off)")
        return None

    def check_servo(self, where: str) -> MotorModel:
        """This model, if the controller or the torque estimator can use it.

        Raises:
            IdentificationError: ``<where>: field '<key>' <value>: expected ...`` (see :meth:`servo_issue`).
        """
        issue = self.servo_issue()
        if issue is not None:
            raise IdentificationError(f"{where}: field '{issue[0]}' {issue[1]}")
        return self

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

    @classmethod
    def from_terms(
        cls,
        mt: ModelTerms,
        loss: Loss,
        provenance: str,
        metrics: FitMetrics | None = None,
        *,
        target: str = SERVO_ERROR,
        unit: str = SERVO_UNIT,
    ) -> MotorModel:
        """The model of :meth:`terms` (its inverse): ``k_tau``, ``k_v``, ``offset`` from the linear
        coefficients (``k_tau`` and ``offset`` only if in ``mt.linear``); ``coulomb`` with a plain sign and a
        coefficient >= 0 becomes ``k_c``, every other term an extra term with its shape.

        Raises:
            IdentificationError: ``k_v`` is not in the model, or a coefficient is out of its range (the
                message names it).
        """
        c = mt.coefficients
        if K_V not in mt.linear:
            raise IdentificationError(f"model coefficients {list(c)}: expected k_v among them (a velocity column)")
        k_c = None
        extra = {}
        for name, shape in mt.terms:
            if name == "coulomb" and k_c is None and shape.get("v_eps", 0.0) == 0.0 and c[name] >= 0.0:
                k_c = c[name]
            else:
                extra[name] = EffectTerm(c[name], shape)
        if target == SERVO_ERROR and unit == SERVO_UNIT and c[K_V] < 0:
            raise IdentificationError(f"fitted k_v = {c[K_V]:.3g}: expected >= 0 for a servo-error motor model; "
                                      "check the data")
        return cls(c[K_TAU] if K_TAU in mt.linear else None, c[K_V], k_c, extra, loss, provenance, metrics,
                   offset=c[OFFSET] if OFFSET in mt.linear else None, target=target, unit=unit)

    def predict(
        self,
        tau: np.ndarray | None,
        dq: np.ndarray,
        *,
        q: np.ndarray | None = None,
        q_des: np.ndarray | None = None,
        t: np.ndarray | None = None,
        ddq: np.ndarray | None = None,
        period: float | None = None,
    ) -> np.ndarray:
        """``[k_tau tau +] k_v dq [+ k_c sign(dq)] [+ offset] [+ extra terms]`` [unit] on arrays of samples
        (``tau`` may be None for a model without ``k_tau``).

        Extra terms are evaluated by the effect registry (:mod:`servotau.actuator.online`); the signals they
        need (``q``, ``q_des``, the time ``t`` or ``period``, the acceleration ``ddq``) must then be given. For
        one tick at a time with the state of effects with memory, use :meth:`online`.

        Raises:
            IdentificationError: An extra term is unknown or needs a signal that was not given.
        """
        if self.extra:
            return predict_batch(self, tau, dq, q=q, q_des=q_des, t=t, ddq=ddq, period=period)
        dq = np.asarray(dq, dtype=np.float64)
        out = self.k_v * dq + (self.k_c or 0.0) * np.sign(dq) + (self.offset or 0.0)
        if self.k_tau is not None:
            if tau is None:
                raise IdentificationError("tau = None: expected the torque [N m] (the model has k_tau)")
            out = out + self.k_tau * np.asarray(tau, dtype=np.float64)
        return out

    def online(self, period: float) -> OnlineModel:
        """An :class:`~servotau.actuator.online.OnlineModel`: this model one control tick at a time
        (``step(tau, dq, q=..., q_des=..., t=..., ddq=...)``), effects with memory included."""
        return OnlineModel(self, period)

    def terms(self) -> ModelTerms:
        """The model as its evaluator reads it: the linear coefficients present (``k_tau``, ``k_v``,
        ``offset``), ``k_c`` as the ``coulomb`` term with a plain sign (``v_eps = 0``), first, then the extra
        terms in order.

        Raises:
            IdentificationError: ``k_c`` and an extra term ``coulomb`` are both set, or a term is unknown.
        """
        linear = tuple(k for k, v in ((K_TAU, self.k_tau), (K_V, self.k_v), (OFFSET, self.offset)) if v is not None)
        coefs = {k: getattr(self, k) for k in linear}
        terms = []
        if self.k_c is not None and "coulomb" in self.extra:
            raise IdentificationError("k_c and an extra term 'coulomb' are both set: expected one Coulomb term")
        if self.k_c is not None:
            terms.append(("coulomb", {"v_eps": 0.0}))
            coefs["coulomb"] = self.k_c
        for name, term in self.extra.items():
            terms.append((name, dict(term.shape)))
            coefs[name] = term.coefficient
        return ModelTerms(linear, tuple(terms), coefs)


