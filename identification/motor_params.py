"""Identified actuator model per joint and its TOML file (e.g. ``config/motors/<robot>.toml``).

Model of one joint: ``dq_err = k_tau tau + k_v dq [+ k_c sign(dq)] [+ sum_e coefficient_e phi_e]``.

File format (``version = 1``)::

    version = 1

    [joints.RLEG_JOINT3]
    k_tau = 5.1e-05            # [rad/(N m)], > 0
    k_v = 0.006561             # [rad/(rad/s)], >= 0
    k_c = 0.0001               # [rad], >= 0, optional
    loss = "asymmetric"        # or "least_squares" (then no w)
    w = 10.0                   # over-estimation weight, > 1
    provenance = "runs/ident_2025-01-01.parquet; 2025-01-01; backend=mujoco"

    [joints.RLEG_JOINT3.metrics]   # optional
    rms = 0.00012              # [rad], >= 0
    overestimation_rate = 0.04 # in [0, 1]
    n_samples = 20000

    [joints.RLEG_JOINT3.extra.deadzone]   # optional, any number of terms
    coefficient = 0.001
    shape = { e_deadzone = 0.003 }
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from servotau.config import Section, load_toml
from servotau.errors import IdentificationError

from . import toml_writer as tw
from .linear_fit import LinearFit
from .loss import LOSS_KINDS, Loss
from .regressors import K_C, K_TAU, K_V, sign
from .two_stage import TwoStageFit

FORMAT_VERSION = 1


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
        fit: LinearFit | TwoStageFit,
        provenance: str,
        extra_shapes: Mapping[str, Mapping[str, float]] | None = None,
    ) -> MotorModel:
        """Model from a fit: ``k_tau``, ``k_v``, ``k_c`` by name, any other coefficient as an extra term
        with shape parameters from ``extra_shapes``. A two-stage fit records the moving stage's loss and
        notes both in ``provenance`` if they differ."""
        coefs = dict(fit.coefficients)
        missing = [k for k in (K_TAU, K_V) if k not in coefs]
        if missing:
            raise IdentificationError(f"fit coefficients {list(coefs)}: expected {missing} among them")
        if isinstance(fit, TwoStageFit):
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

        Extra terms are evaluated by the effect registry of the model workbench
        (:mod:`servotau.identification.workbench.online`); the signals they need (``q``, ``q_des``, the
        time ``t`` or ``period``, the acceleration ``ddq``) must then be given. For one tick at a time
        with the state of effects with memory, use :meth:`online`.

        Raises:
            IdentificationError: An extra term is unknown or needs a signal that was not given.
        """
        if self.extra:
            from .workbench.online import predict_batch  # the registry lives in the workbench

            return predict_batch(self, tau, dq, q=q, q_des=q_des, t=t, ddq=ddq, period=period)
        tau = np.asarray(tau, dtype=np.float64)
        dq = np.asarray(dq, dtype=np.float64)
        return self.k_tau * tau + self.k_v * dq + (self.k_c or 0.0) * sign(dq)

    def online(self, period: float):
        """An :class:`~servotau.identification.workbench.online.OnlineModel`: this model one control tick
        at a time (``step(tau, dq, q=..., q_des=..., t=..., ddq=...)``), effects with memory included."""
        from .workbench.online import OnlineModel

        return OnlineModel(self, period)


@dataclass(frozen=True)
class MotorParameters(Mapping[str, MotorModel]):
    """Motor models by joint name, saved to and loaded from TOML."""

    models: Mapping[str, MotorModel]

    def __post_init__(self) -> None:
        for name, m in self.models.items():
            if not isinstance(name, str) or not name or not isinstance(m, MotorModel):
                raise IdentificationError(f"joint {name!r}: expected a MotorModel under a non-empty joint name")
        object.__setattr__(self, "models", dict(self.models))

    def __getitem__(self, joint: str) -> MotorModel:
        if joint not in self.models:
            raise IdentificationError(f"joint '{joint}' has no motor model: expected one of {list(self.models)}")
        return self.models[joint]

    def __contains__(self, joint: object) -> bool:
        return joint in self.models  # Mapping's default would turn the clear error above into a crash

    def __iter__(self) -> Iterator[str]:
        return iter(self.models)

    def __len__(self) -> int:
        return len(self.models)

    def save_toml(self, path: str | Path) -> Path:
        """Write the file (format in the module docstring); return its path."""
        lines = [
            "# servotau motor parameters: dq_err = k_tau*tau + k_v*dq [+ k_c*sign(dq)] [+ extra terms]",
            "# Units: k_tau [rad/(N m)], k_v [rad/(rad/s)], k_c [rad], rms [rad].",
            f"version = {FORMAT_VERSION}",
        ]
        for joint, m in self.models.items():
            table = f"joints.{tw.key(joint)}"
            lines += ["", f"[{table}]", f"k_tau = {tw.value(m.k_tau)}", f"k_v = {tw.value(m.k_v)}"]
            if m.k_c is not None:
                lines.append(f"k_c = {tw.value(m.k_c)}")
            lines.append(f"loss = {tw.value(m.loss.kind)}")
            if m.loss.w is not None:
                lines.append(f"w = {tw.value(m.loss.w)}")
            lines.append(f"provenance = {tw.value(m.provenance)}")
            if m.metrics is not None:
                lines += [
                    "",
                    f"[{table}.metrics]",
                    f"rms = {tw.value(m.metrics.rms)}",
                    f"overestimation_rate = {tw.value(m.metrics.overestimation_rate)}",
                    f"n_samples = {tw.value(m.metrics.n_samples)}",
                ]
            for name, term in m.extra.items():
                lines += [
                    "",
                    f"[{table}.extra.{tw.key(name)}]",
                    f"coefficient = {tw.value(term.coefficient)}",
                    f"shape = {tw.value(dict(term.shape))}",
                ]
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("\n".join(lines) + "\n", encoding="utf-8")
        return p

    @classmethod
    def load_toml(cls, path: str | Path) -> MotorParameters:
        """Read and validate a file.

        Raises:
            ConfigError: Naming the file, the field and the expected value.
        """
        root = load_toml(path)
        root.check_keys(["version", "joints"])
        version = root.int("version")
        if version != FORMAT_VERSION:
            raise root.error("version", version, f"{FORMAT_VERSION}")
        joints = root.section("joints")
        if not joints.keys():
            raise root.error("joints", {}, "at least one joint table")
        return cls({name: _load_model(joints.section(name)) for name in joints.keys()})


def _load_model(sec: Section) -> MotorModel:
    sec.check_keys(["k_tau", "k_v", "k_c", "loss", "w", "provenance", "metrics", "extra"])
    kind = sec.str("loss", choices=LOSS_KINDS)
    if kind == "asymmetric":
        loss = Loss(kind, sec.float("w", min=1.0, strict_min=True))
    elif "w" in sec:
        raise sec.error("w", sec.data["w"], 'no w with loss = "least_squares"')
    else:
        loss = Loss(kind)
    provenance = sec.str("provenance")
    if not provenance:
        raise sec.error("provenance", provenance, "a non-empty string (log file, date, backend)")
    metrics = None
    if "metrics" in sec:
        ms = sec.section("metrics")
        ms.check_keys(["rms", "overestimation_rate", "n_samples"])
        metrics = FitMetrics(
            ms.float("rms", min=0.0, unit="rad"),
            ms.float("overestimation_rate", min=0.0, max=1.0),
            ms.int("n_samples", min=0),
        )
    extra = {}
    for name in sec.section("extra", {}).keys():
        es = sec.section("extra").section(name)
        es.check_keys(["coefficient", "shape"])
        shape = es.section("shape", {})
        extra[name] = EffectTerm(es.float("coefficient"), {k: shape.float(k) for k in shape.keys()})
    return MotorModel(
        k_tau=sec.float("k_tau", min=0.0, strict_min=True, unit="rad/(N m)"),
        k_v=sec.float("k_v", min=0.0, unit="rad/(rad/s)"),
        k_c=sec.float("k_c", min=0.0, unit="rad") if "k_c" in sec else None,
        extra=extra,
        loss=loss,
        provenance=provenance,
        metrics=metrics,
    )
