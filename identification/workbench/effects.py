"""Named physical effects: regressors of the actuator model with a grid of shape parameters.

An :class:`Effect` adds ``coefficient * phi(signals; shape)`` [rad] to the model
``dq_err = k_tau tau + k_v dq + ...``. The registry maps names to effects; the library of built-in
effects (:mod:`~servotau.identification.workbench.library`) fills it at import, and users add their
own without editing it::

    from servotau.identification.workbench import register_effect

    register_effect(
        "cubic_torque",
        lambda s, tau_ref: (s["tau"] / tau_ref) ** 3,     # any function of the log columns
        grid=[{"tau_ref": 10.0}, {"tau_ref": 30.0}],      # shapes to try [N m]
        signals=("tau",),
        signature="residual against torque bends like a cubic",
    )
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from servotau.errors import IdentificationError

from .signals import Signals

FAMILIES = ("velocity", "torque", "servo_error", "position", "time", "dynamics", "custom")
"""Signal families of the non-parametric probes; an effect's family names the probe it is compared with."""

Regressor = Callable[..., np.ndarray]
RESERVED = ("k_tau", "k_v", "k_c", "paper")


class OnlineTerm(Protocol):
    """On-line evaluation of one term, one sample at a time (``sample`` maps signal names to floats)."""

    def value(self, sample: Mapping[str, float]) -> float:
        """The regressor at this sample, state not advanced (may be called several times)."""

    def commit(self, sample: Mapping[str, float]) -> None:
        """Advance the state with this sample (once per tick, after :meth:`value`)."""


@dataclass(frozen=True)
class Effect:
    """A physical effect as one regressor column of the actuator model.

    Attributes:
        name: Registry key, also the key of the term in the motor-parameter file.
        regressor: ``phi(signals, **shape) -> (n,)`` array [unit of the term / coefficient].
        grid: Shapes tried by the diagnosis (each a mapping of shape parameters), or a function of the
            :class:`Signals` giving them (e.g. thresholds at quantiles of the data).
        signals: Signals the regressor reads (see :mod:`~servotau.identification.workbench.signals`);
            on-line evaluation needs the same.
        signature: How the missing effect shows in the residuals (documentation, reports).
        family: The non-parametric probe it is compared with (one of :data:`FAMILIES`).
        description: One line of physics.
        needs: ``needs(excitation) -> str | None``: why the data cannot test the effect, or None.
        fit_columns: ``(signals, **shape) -> (n, k)`` columns fitted instead of ``regressor`` (e.g. sine
            and cosine of a ripple of unknown phase); then ``fold`` turns their ``k`` coefficients into
            one coefficient and the full shape, so that ``regressor`` reproduces the fitted sum.
        fold: See ``fit_columns``.
        online: ``online(shape, period) -> OnlineTerm`` for effects with memory; None: the regressor is
            evaluated on the current sample alone.
        history: The regressor reads past samples (needs a uniform sampling period).
        confusable: Effects whose columns may look alike on poor data (see ``experiments``).
        coefficient_range: ``(low, high)``: the coefficients the physics allows (e.g. a fraction); a shape whose
            fit gives a coefficient outside is not chosen (the term would be a generic correction, not the
            effect). None: any coefficient.
        shape_signals: ``shape_signals(shape) -> names``: signals that some shapes read besides ``signals``
            (e.g. the crossing form of ``deadzone`` reads ``q`` and ``q_des``); a grid function should offer
            such shapes only when the signals are there.
    """

    name: str
    regressor: Regressor
    grid: tuple[Mapping[str, float], ...] | Callable[[Signals], Iterable[Mapping[str, float]]] = ({},)
    signals: tuple[str, ...] = ()
    signature: str = ""
    family: str = "custom"
    description: str = ""
    needs: Callable[[object], str | None] | None = None
    fit_columns: Callable[..., np.ndarray] | None = None
    fold: Callable[[np.ndarray, Mapping[str, float]], tuple[float, dict[str, float]]] | None = None
    online: Callable[[Mapping[str, float], float], OnlineTerm] | None = None
    history: bool = False
    confusable: tuple[str, ...] = ()
    coefficient_range: tuple[float, float] | None = None
    shape_signals: Callable[[Mapping[str, float]], Iterable[str]] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.isidentifier() or self.name in RESERVED:
            raise IdentificationError(
                f"effect name {self.name!r}: expected an identifier (letters, digits, _) other than {list(RESERVED)}"
            )
        if not callable(self.regressor):
            raise IdentificationError(f"effect '{self.name}': regressor {self.regressor!r}: expected a callable")
        if not callable(self.grid):
            object.__setattr__(self, "grid", _check_grid(self.name, self.grid))
        object.__setattr__(self, "signals", tuple(self.signals))
        object.__setattr__(self, "confusable", tuple(self.confusable))
        if self.family not in FAMILIES:
            raise IdentificationError(f"effect '{self.name}': family {self.family!r}: expected one of {FAMILIES}")
        if (self.fit_columns is None) != (self.fold is None):
            raise IdentificationError(f"effect '{self.name}': expected both fit_columns and fold, or neither")
        if self.coefficient_range is not None:
            low, high = (float(v) for v in self.coefficient_range)
            if not low < high or self.fit_columns is not None:
                raise IdentificationError(
                    f"effect '{self.name}': coefficient_range {self.coefficient_range!r}: expected (low, high) with "
                    "low < high, for a one-column effect (no fit_columns)"
                )
            object.__setattr__(self, "coefficient_range", (low, high))

    @property
    def uses_model(self) -> bool:
        """The regressor reads ``u``, ``u_tau`` or ``u_v``: signals of the model it is added to."""
        return bool({"u", "u_tau", "u_v"} & set(self.signals))

    def signals_of(self, shape: Mapping[str, float]) -> tuple[str, ...]:
        """The signals the term of ``shape`` reads: ``signals`` and those of ``shape_signals``."""
        extra = tuple(self.shape_signals(shape)) if self.shape_signals is not None else ()
        return self.signals + tuple(x for x in extra if x not in self.signals)

    def evaluate(self, signals: Signals, shape: Mapping[str, float]) -> np.ndarray:
        """``phi`` [n] at ``shape``, checked to be finite and of the right length."""
        return _column(self, self.regressor, signals, shape, 1)[:, 0]

    def columns(self, signals: Signals, shape: Mapping[str, float]) -> np.ndarray:
        """Columns fitted for ``shape``: ``(n, k)`` (parameters added by ``fold``, e.g. a phase, are ignored)."""
        if self.fit_columns is None:
            return _column(self, self.regressor, signals, shape, None)
        if not callable(self.grid):
            shape = {k: v for k, v in shape.items() if k in self.grid[0]}
        return _column(self, self.fit_columns, signals, shape, None)

    def folded(self, coefs: np.ndarray, shape: Mapping[str, float]) -> tuple[float, dict[str, float]]:
        """The term's ``(coefficient, shape)`` from the fitted coefficients of :meth:`columns`."""
        if self.fold is None:
            return float(coefs[0]), dict(shape)
        c, full = self.fold(np.asarray(coefs, dtype=np.float64), dict(shape))
        return float(c), {k: float(v) for k, v in full.items()}

    def admits(self, coefficient: float) -> bool:
        """The fitted ``coefficient`` is one the physics allows (see ``coefficient_range``)."""
        if self.coefficient_range is None:
            return True
        low, high = self.coefficient_range
        return low <= coefficient <= high

    def grid_for(self, signals: Signals) -> tuple[dict[str, float], ...]:
        """The shapes to try on ``signals``."""
        if callable(self.grid):
            return _check_grid(self.name, self.grid(signals))
        return self.grid


def _check_grid(name: str, grid: Iterable[Mapping[str, float]]) -> tuple[dict[str, float], ...]:
    out = tuple(dict(g) for g in grid) or ({},)
    for g in out:
        for k, v in g.items():
            if not isinstance(k, str) or isinstance(v, bool) or not isinstance(v, (int, float, np.floating)):
                raise IdentificationError(f"effect '{name}': grid entry {g!r}: expected name -> number")
            if not math.isfinite(v):
                raise IdentificationError(f"effect '{name}': grid entry {g!r}: expected finite numbers")
    return tuple({k: float(v) for k, v in g.items()} for g in out)


def _column(effect: Effect, fn: Regressor, signals: Signals, shape: Mapping[str, float], k: int | None) -> np.ndarray:
    try:
        out = fn(signals, **shape)
    except IdentificationError:
        raise
    except TypeError as exc:
        raise IdentificationError(
            f"effect '{effect.name}': regressor failed with shape {dict(shape)}: {exc}: expected the shape "
            "parameters of its grid"
        ) from exc
    out = np.asarray(out, dtype=np.float64)
    if out.ndim == 1:
        out = out[:, None]
    if out.ndim != 2 or out.shape[0] != signals.n or (k is not None and out.shape[1] != k):
        raise IdentificationError(
            f"effect '{effect.name}': regressor returned shape {out.shape}: expected ({signals.n},)"
        )
    bad = ~np.isfinite(out)
    if bad.any():
        raise IdentificationError(
            f"effect '{effect.name}' with shape {dict(shape)}: {int(bad.any(axis=1).sum())} samples are NaN or inf: "
            "expected finite regressor values"
        )
    return out


@dataclass
class _Registry:
    effects: dict[str, Effect] = field(default_factory=dict)


_REGISTRY = _Registry()


def register_effect(
    effect: Effect | str,
    regressor: Regressor | None = None,
    *,
    replace: bool = False,
    **fields,
) -> Effect:
    """Add an effect to the registry and return it.

    Either pass an :class:`Effect`, or a name, a regressor ``phi(signals, **shape)`` and any other
    :class:`Effect` field (``grid``, ``signals``, ``signature``, ...). ``signals`` maps names to arrays:
    the standard signals and every column of the log.

    Raises:
        IdentificationError: The name is taken (unless ``replace``) or a field is invalid.
    """
    if not isinstance(effect, Effect):
        if regressor is None:
            raise IdentificationError(f"register_effect('{effect}'): expected a regressor function")
        effect = Effect(name=effect, regressor=regressor, **fields)
    elif regressor is not None or fields:
        raise IdentificationError("register_effect(Effect(...)): expected no other arguments")
    if effect.name in _REGISTRY.effects and not replace:
        raise IdentificationError(f"effect '{effect.name}' is already registered: pass replace=True to redefine it")
    _REGISTRY.effects[effect.name] = effect
    return effect


def unregister_effect(name: str) -> None:
    """Remove a user effect (built-in effects can be removed too, e.g. in tests)."""
    get_effect(name)
    del _REGISTRY.effects[name]


def get_effect(name: str) -> Effect:
    """The registered effect ``name``, or raise listing the known names."""
    if name not in _REGISTRY.effects:
        raise IdentificationError(f"unknown effect '{name}': expected one of {effect_names()}")
    return _REGISTRY.effects[name]


def effect_names() -> list[str]:
    """Registered effect names, built-in ones first in library order."""
    return list(_REGISTRY.effects)


def resolve_effects(names: Iterable[str] | None) -> list[Effect]:
    """Effects by name (all registered ones for None), each name checked."""
    if names is None:
        return list(_REGISTRY.effects.values())
    return [get_effect(n) for n in names]
