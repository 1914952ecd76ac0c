"""The effect registry: named physical effects, regressors of the actuator model with a grid of shapes.

An :class:`Effect` adds ``coefficient * phi(signals; shape)`` [rad] to the model
``dq_err = k_tau tau + k_v dq + ...``. The built-in effects are the modules of
:mod:`servotau.actuator.effects`, one file per effect, found on first use of the registry (in the order of
their ``ORDER``); users add their own without editing it::

    from servotau.actuator import register_effect

    register_effect(
        "cubic_torque",
        lambda s, tau_ref: (s["tau"] / tau_ref) ** 3,     # any function of the log columns
        grid=[{"tau_ref": 10.0}, {"tau_ref": 30.0}],      # shapes to try [N m]
        signals=("tau",),
        signature="residual against torque bends like a cubic",
    )
"""

from __future__ import annotations

import importlib
import math
import pkgutil
from collections.abc import Callable, Iterable, Iterator, Mapping
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
        signals: Signals the regressor reads (see :mod:`~servotau.actuator.signals`); on-line evaluation
            needs the same.
        signature: How the missing effect shows in the residuals (documentation, reports).
        family: The non-parametric probe it is compared with (one of :data:`FAMILIES`).
        description: One line of physics.
        needs: ``needs(excitation) -> str | None``: why the data cannot test the effect, or None.
        lookalike_needs: ``lookalike_needs(excitation) -> str | None``: the part of ``needs`` whose reason is only
            that the log cannot tell this effect from ``needs_lookalikes`` (e.g. a dead zone from Coulomb friction
            without a torque reversal at rest). That reason holds on a log only where one of them removes a
            comparable error: where each was scored (or is in the model) and removes at most the diagnosis's
            ``LOOKALIKE_SHARE`` of what this effect removes, the effect is tested and the diagnosis says why.
        needs_lookalikes: The effects ``lookalike_needs`` is about.
        fit_columns: ``(signals, **shape) -> (n, k)`` columns fitted instead of ``regressor`` (e.g. sine
            and cosine of a ripple of unknown phase); then ``fold`` turns their ``k`` coefficients into
            one coefficient and the full shape, so that ``regressor`` reproduces the fitted sum.
        fold: See ``fit_columns``.
        online: ``online(shape, period) -> OnlineTerm`` for effects with memory; None: the regressor is
            evaluated on the current sample alone.
        history: The regressor reads past samples (needs a uniform sampling period).
        confusable: Effects whose columns may look alike on poor data (see ``experiments``).
        nests: Effects this one contains as a special case (e.g. a Stribeck curve of level 1 is Coulomb friction):
            the diagnosis ranks it above them only where its extra freedom pays in every held-out block.
        coefficient_range: ``(low, high)``: the coefficients the physics allows (e.g. a fraction); a shape whose
            fit gives a coefficient outside is not chosen (the term would be a generic correction, not the
            effect). None: any coefficient.
        shape_signals: ``shape_signals(shape) -> names``: signals that some shapes read besides ``signals``
            (e.g. the crossing form of ``deadzone`` reads ``q`` and ``q_des``); a grid function should offer
            such shapes only when the signals are there.
        scalar: ``scalar(sample, **shape) -> float``: ``regressor`` on one sample (a mapping of floats), for
            the on-line evaluation of an effect without memory; None: the regressor on one-sample arrays.
        online_signals: What a controller must provide on-line for this effect, on top of ``tau`` and ``dq``
            (documentation, error messages).
        signal_substitutes: Signals another one stands for: ``{"q": "ddq"}``: the regressor filters ``q``
            into an acceleration only when no acceleration is given (on-line: the estimator's ``ddq``).
        experiments: The experiment that tells this effect from a look-alike, by the look-alike's name (each
            pair is written in one of its two effects' files; see :func:`experiments`).
        phi_unit: Unit of the regressor ``phi``: ``"1"`` dimensionless, ``"target"`` the target's own unit, else a
            unit (``"N m"``, ``"rad/s^2"``); the coefficient is in [target unit / unit of phi]. A mapping when the
            unit depends on the shape: ``{form: unit}`` (e.g. ``thermal_drift``'s two forms). None: not given.
        shape_text: ``shape_text(coefficient, shape) -> str``: how a fitted term reads in a verdict where its shape
            alone would mislead (``delay``'s velocity form: the dead time its coefficient gives). None: the shape.
    """

    name: str
    regressor: Regressor
    grid: tuple[Mapping[str, float], ...] | Callable[[Signals], Iterable[Mapping[str, float]]] = ({},)
    signals: tuple[str, ...] = ()
    signature: str = ""
    family: str = "custom"
    description: str = ""
    needs: Callable[[object], str | None] | None = None
    lookalike_needs: Callable[[object], str | None] | None = None
    needs_lookalikes: tuple[str, ...] = ()
    fit_columns: Callable[..., np.ndarray] | None = None
    fold: Callable[[np.ndarray, Mapping[str, float]], tuple[float, dict[str, float]]] | None = None
    online: Callable[[Mapping[str, float], float], OnlineTerm] | None = None
    history: bool = False
    confusable: tuple[str, ...] = ()
    nests: tuple[str, ...] = ()
    coefficient_range: tuple[float, float] | None = None
    shape_signals: Callable[[Mapping[str, float]], Iterable[str]] | None = None
    scalar: Callable[..., float] | None = None
    online_signals: str = ""
    signal_substitutes: Mapping[str, str] = field(default_factory=dict)
    experiments: Mapping[str, str] = field(default_factory=dict)
    phi_unit: str | Mapping[str, str] | None = None
    shape_text: Callable[[float, Mapping[str, float]], str] | None = None

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
        object.__setattr__(self, "nests", tuple(self.nests))
        object.__setattr__(self, "needs_lookalikes", tuple(self.needs_lookalikes))
        object.__setattr__(self, "signal_substitutes", dict(self.signal_substitutes))
        object.__setattr__(self, "experiments", dict(self.experiments))
        if self.phi_unit is not None and not isinstance(self.phi_unit, str):
            object.__setattr__(self, "phi_unit", dict(self.phi_unit))
        if self.family not in FAMILIES:
            raise IdentificationError(f"effect '{self.name}': family {self.family!r}: expected one of {FAMILIES}")
        if (self.lookalike_needs is None) != (not self.needs_lookalikes):
            raise IdentificationError(f"effect '{self.name}': expected both lookalike_needs and needs_lookalikes, "
                                      "or neither")
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

    def shape_minimums(self) -> dict[str, float]:
        """The shape parameters that every shape of a fixed grid holds at 0 or more (a width, a time constant, a
        speed), each mapped to 0: a motor file's value below it is refused. Empty for a grid computed from the
        data."""
        shapes = getattr(self.grid, "shapes", None if callable(self.grid) else self.grid) or ()
        keys = {k for g in shapes for k in g}
        return {k: 0.0 for k in sorted(keys) if all(g[k] >= 0 for g in shapes if k in g)}

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
    builtin: tuple[Effect, ...] | None = None  # None until the effect files are loaded


_REGISTRY = _Registry()
EFFECTS_PACKAGE = __name__.rsplit(".", 1)[0] + ".effects"


def _discover() -> tuple[Effect, ...]:
    """The effects of the files of :mod:`servotau.actuator.effects`, ordered by their ``ORDER``.

    Each module ``<name>.py`` (not starting with ``_``) defines ``EFFECT``, an :class:`Effect` named
    ``<name>``, and ``ORDER``, its place in the library (rankings keep this order on ties).
    """
    package = importlib.import_module(EFFECTS_PACKAGE)
    found = []
    for info in pkgutil.iter_modules(package.__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{EFFECTS_PACKAGE}.{info.name}")
        effect, order = getattr(module, "EFFECT", None), getattr(module, "ORDER", None)
        if not isinstance(effect, Effect) or effect.name != info.name:
            raise IdentificationError(f"{module.__file__}: EFFECT = {effect!r}: expected an Effect named '{info.name}'")
        if isinstance(order, bool) or not isinstance(order, int):
            raise IdentificationError(f"{module.__file__}: ORDER = {order!r}: expected an int (the library order)")
        found.append((order, effect))
    orders = [o for o, _ in found]
    if len(set(orders)) != len(orders):
        raise IdentificationError(f"effect files of {EFFECTS_PACKAGE}: ORDER = {sorted(orders)}: expected distinct")
    return tuple(e for _, e in sorted(found, key=lambda oe: oe[0]))


def _effects() -> dict[str, Effect]:
    """The registry, the built-in effects loaded first (on first use)."""
    if _REGISTRY.builtin is None:
        _REGISTRY.builtin = ()  # a file that uses the registry while it is loaded sees it empty, not a recursion
        try:
            builtin = _discover()
        except BaseException:
            _REGISTRY.builtin = None
            raise
        _REGISTRY.builtin = builtin
        _REGISTRY.effects = {**{e.name: e for e in builtin}, **_REGISTRY.effects}
    return _REGISTRY.effects


def builtin_effects() -> tuple[Effect, ...]:
    """The built-in effects (one file each in :mod:`servotau.actuator.effects`), in library order."""
    _effects()
    return _REGISTRY.builtin


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
    effects = _effects()
    if effect.name in effects and not replace:
        raise IdentificationError(f"effect '{effect.name}' is already registered: pass replace=True to redefine it")
    effects[effect.name] = effect
    return effect


def unregister_effect(name: str) -> None:
    """Remove a user effect (built-in effects can be removed too, e.g. in tests)."""
    get_effect(name)
    del _effects()[name]


def get_effect(name: str) -> Effect:
    """The registered effect ``name``, or raise listing the known names."""
    effects = _effects()
    if name not in effects:
        raise IdentificationError(f"unknown effect '{name}': expected one of {effect_names()}")
    return effects[name]


def effect_names() -> list[str]:
    """Registered effect names, built-in ones first in library order."""
    return list(_effects())


def resolve_effects(names: Iterable[str] | None) -> list[Effect]:
    """Effects by name (all registered ones for None), each name checked."""
    if names is None:
        return list(_effects().values())
    return [get_effect(n) for n in names]


class _View(Mapping):
    """A read-only mapping computed from the registry at each access (it follows registrations)."""

    def __init__(self, build: Callable[[], dict]):
        self._build = build

    def __getitem__(self, key):
        return self._build()[key]

    def __iter__(self) -> Iterator:
        return iter(self._build())

    def __len__(self) -> int:
        return len(self._build())

    def __repr__(self) -> str:
        return repr(self._build())


def _experiments() -> dict[frozenset[str], str]:
    out: dict[frozenset[str], str] = {}
    for effect in _effects().values():
        for other, text in effect.experiments.items():
            key = frozenset((effect.name, other))
            if out.get(key, text) != text:
                raise IdentificationError(f"effects '{effect.name}' and '{other}': two different experiments: "
                                          "expected the pair's experiment in one of the two effect files")
            out[key] = text
    return out


EXPERIMENTS: Mapping[frozenset[str], str] = _View(_experiments)
"""The experiment that separates two look-alike effects, by the pair ``frozenset((a, b))``."""

ONLINE_SIGNALS: Mapping[str, str] = _View(
    lambda: {e.name: e.online_signals for e in _effects().values() if e.online_signals}
)
"""What the controller must provide on-line for each effect, on top of the paper's ``tau`` and ``dq``."""
