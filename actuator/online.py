"""Evaluate a :class:`~servotau.actuator.model.MotorModel` with extra terms, off-line on arrays or on-line one
control tick at a time (for the feedforward of control/).

The signals each effect needs on-line are its ``online_signals`` (:data:`ONLINE_SIGNALS`): the controller gives
``tau`` [N m] (desired or estimated torque), ``dq`` [rad/s], ``q`` [rad], ``q_des`` [rad] (the command of this
tick), ``t`` [s] and, for the effects whose ``signal_substitutes`` map ``q`` to ``ddq`` (``elastic``,
``backlash``), the estimator's ``ddq`` [rad/s^2] (off-line the workbench filters ``q`` with the term's
``window``; given ``ddq``, :func:`predict_batch` uses it instead, as on-line). Effects with memory (an
``online`` state class) keep their state in the :class:`OnlineModel`; call :meth:`OnlineModel.step` exactly
once per tick.

An effect that reads the command of the current tick (``delay``) makes the model affine in ``q_des``:
:meth:`OnlineModel.command` solves ``q_des = q + model(q_des)`` for the feedforward.

The model's linear part is that of its ``terms()``: ``k_tau tau`` only if the model has ``k_tau`` (else
``tau`` is not read and may be None), ``k_v dq``, and the constant ``offset`` if it has one, on-line as in
the batch evaluation.

The model is anything with ``extra`` (effect terms with ``shape``) and ``terms()`` (a
:class:`~servotau.actuator.terms.ModelTerms`): a :class:`~servotau.actuator.model.MotorModel`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from servotau.errors import IdentificationError

from .registry import ONLINE_SIGNALS, get_effect
from .signals import Signals
from .terms import K_TAU, K_V, OFFSET

BASE_SIGNALS = ("tau", "dq")
MODEL_SIGNALS = ("u", "u_tau", "u_v")  # computed from the model, not given

__all__ = ["BASE_SIGNALS", "ONLINE_SIGNALS", "OnlineModel", "checked_online_model", "predict_batch",
           "required_signals"]


def required_signals(model) -> list[str]:
    """Signals (besides ``tau`` and ``dq``) that evaluating ``model`` needs."""
    out: list[str] = []
    for name, term in model.extra.items():
        eff = get_effect(name)
        for s in eff.signals_of(term.shape):
            s = eff.signal_substitutes.get(s, s)
            if s not in (*BASE_SIGNALS, *MODEL_SIGNALS) and s not in out:
                out.append(s)
        if eff.history and "t" not in out:
            out.append("t")
    return out


def predict_batch(
    model,
    tau: np.ndarray | None,
    dq: np.ndarray,
    *,
    q: np.ndarray | None = None,
    q_des: np.ndarray | None = None,
    t: np.ndarray | None = None,
    ddq: np.ndarray | None = None,
    period: float | None = None,
    columns: Mapping[str, np.ndarray] | None = None,
) -> np.ndarray:
    """``model`` on arrays of samples [unit of its target]; ``period`` [s] defaults to the median step of ``t``;
    ``tau`` may be None if neither ``k_tau`` nor an effect reads it.

    Raises:
        IdentificationError: A term needs a signal that was not given (the message names both).
    """
    dq = np.asarray(dq, dtype=np.float64)
    n = len(dq)
    cols: dict[str, np.ndarray] = {**(columns or {}), "dq": dq}
    for name, v in (("tau", tau), ("q", q), ("q_des", q_des), ("t", t), ("ddq", ddq), ("ddq_est", ddq)):
        if v is not None:
            cols[name] = np.asarray(v, dtype=np.float64)
    for name, v in cols.items():
        if v.shape != (n,):
            raise IdentificationError(f"signal '{name}': shape {v.shape}: expected ({n},) like dq")
    if period is None and "t" in cols and n > 1:
        period = float(np.median(np.diff(cols["t"])))
    _check_signals(model, cols, period)
    return model.terms().predict(Signals(cols, period, n))


def _check_signals(model, cols: Mapping[str, object], period: float | None) -> None:
    if K_TAU in model.terms().linear and "tau" not in cols:
        raise IdentificationError("signal 'tau' missing: expected the torque [N m] (the model has k_tau)")
    for name, term in model.extra.items():
        eff = get_effect(name)
        need = [s for s in eff.signals_of(term.shape) if s not in MODEL_SIGNALS]
        need = [eff.signal_substitutes.get(s, s) if s not in cols else s for s in need]
        missing = [s for s in need if s not in cols]
        if missing:
            raise IdentificationError(
                f"extra term '{name}' needs signal(s) {missing}: expected them as keyword arguments "
                f"(on-line: {eff.online_signals or ', '.join(eff.signals)})"
            )
        if eff.history and period is None:
            raise IdentificationError(f"extra term '{name}' has memory: expected the sampling period (or t)")


class _Stateless:
    """An effect without memory, evaluated on the current sample (its ``scalar`` formula if it has one, else
    the regressor on one-sample arrays)."""

    def __init__(self, effect, shape: Mapping[str, float], period: float):
        self.effect, self.shape, self.period = effect, dict(shape), period
        self._scalar = effect.scalar

    def value(self, x: Mapping[str, float]) -> float:
        if self._scalar is not None:
            return float(self._scalar(x, **self.shape))
        cols = {k: np.array([v]) for k, v in x.items()}
        return float(self.effect.evaluate(Signals(cols, self.period, 1), self.shape)[0])

    def commit(self, x: Mapping[str, float]) -> None:
        pass


class OnlineModel:
    """A motor model evaluated one tick at a time, with the state of its effects.

    Args:
        model: The motor model.
        period: Control period [s].
    """

    def __init__(self, model, period: float):
        if not (isinstance(period, (int, float)) and math.isfinite(period) and period > 0):
            raise IdentificationError(f"period = {period!r}: expected a control period > 0 [s]")
        self.model = model
        self.period = float(period)
        self._model_terms = model.terms()
        self._terms = []
        for name, shape in self._model_terms.terms:
            eff = get_effect(name)
            term = eff.online(shape, self.period) if eff.online is not None else _Stateless(eff, shape, self.period)
            self._terms.append((name, eff.uses_model, self._model_terms.coefficients[name], term))
        self.signals = ("tau", "dq", *required_signals(model))
        lin = self._model_terms.linear
        self._needs_tau = K_TAU in lin or any("tau" in get_effect(n).signals_of(s) for n, s in self._model_terms.terms)

    def _sample(self, tau: float | None, dq: float, extra: Mapping[str, float]) -> dict[str, float]:
        if tau is None and self._needs_tau:
            raise IdentificationError("OnlineModel: tau = None: expected the torque [N m] (the model reads it)")
        x = {"tau": 0.0 if tau is None else float(tau), "dq": float(dq)}
        for k, v in extra.items():
            if v is not None:
                x[k] = float(v)
        if "ddq" in x:
            x["ddq_est"] = x["ddq"]  # the estimator's acceleration, as in the batch evaluation
        missing = [s for s in self.signals if s not in x]
        if missing:
            raise IdentificationError(f"OnlineModel: missing signal(s) {missing}: expected {list(self.signals)}")
        c, lin = self._model_terms.coefficients, self._model_terms.linear
        x["u_tau"] = c[K_TAU] * x["tau"] if K_TAU in lin else 0.0
        x["u_v"] = c[K_V] * x["dq"] if K_V in lin else 0.0
        x["u"] = x["u_tau"] + x["u_v"] + (c[OFFSET] if OFFSET in lin else 0.0)
        return x

    def _value(self, x: dict[str, float]) -> float:
        u = x["u"]
        for _, uses_u, c, term in self._terms:
            if not uses_u:
                u += c * term.value(x)
        x["u"] = u
        out = u
        for _, uses_u, c, term in self._terms:
            if uses_u:
                out += c * term.value(x)
        return out

    def predict(self, tau: float | None, dq: float, **signals: float) -> float:
        """The model [its unit; rad for a servo error] at this tick, state not advanced."""
        return self._value(self._sample(tau, dq, signals))

    def step(self, tau: float | None, dq: float, **signals: float) -> float:
        """The model [its unit] at this tick, then advance the state (once per tick)."""
        x = self._sample(tau, dq, signals)
        out = self._value(x)
        for *_, term in self._terms:
            term.commit(x)
        return out

    def command(self, q: float, tau: float | None, dq: float, **signals: float) -> float:
        """The command ``q_des`` [rad] with ``q_des - q = model(q_des)`` (the model is affine in ``q_des``),
        and advance the state with it."""
        if "q_des" not in self.signals:
            q_des = q + self.predict(tau, dq, q=q, **signals)
        else:
            a = self.predict(tau, dq, q=q, q_des=q, **signals)
            b = self.predict(tau, dq, q=q, q_des=q + 1.0, **signals)
            slope = b - a
            if abs(1.0 - slope) < 1e-9:
                raise IdentificationError("model slope in q_des is 1: the command cannot be solved for")
            q_des = q + a / (1.0 - slope)
        self.step(tau, dq, q=q, q_des=q_des, **signals)
        return q_des


def checked_online_model(model, period: float) -> OnlineModel:
    """The on-line model of ``model``, checked on one sample of every signal (zeros).

    Raises:
        IdentificationError: An extra term or its shape parameters cannot be evaluated:
            ``motor-model extra terms [...]: <why>``.
    """
    try:
        om = OnlineModel(model, period)
        om.predict(0.0, 0.0, q=0.0, q_des=0.0, t=0.0, ddq=0.0)
    except (IdentificationError, KeyError, TypeError, ValueError) as err:
        raise IdentificationError(f"motor-model extra terms {list(model.extra)}: {err}") from err
    return om
