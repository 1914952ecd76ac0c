"""A model of the workbench: the paper's linear part plus effect terms, its fit and its conversions.

``dq_err = k_tau tau + k_v dq [+ offset] + sum_e c_e phi_e(signals; shape_e)``

``offset`` is an optional constant term of the base (a general table's target may sit off zero; a servo
log's base has none unless asked for, so its results are those without it).

Terms whose regressor reads ``u`` (the model's servo error without such terms, see
:meth:`FittedModel.context`) are fitted by a fixed point: ``u`` from the previous fit (first the model
without them), fit, update ``u``, fit again (``FIXED_POINT`` rounds). Each round's model is scored as it
will be used, ``u`` from its own coefficients, and the round of least training loss is kept (the
iteration need not converge: a wide dead band leaves the error undetermined inside it).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from servotau.actuator import FitMetrics, Loss, ModelTerms, MotorModel, Signals, get_effect
from servotau.actuator.model import SERVO_ERROR, SERVO_UNIT
from servotau.actuator.terms import K_TAU, K_V, OFFSET
from servotau.errors import IdentificationError

from ..asymmetric import asymmetric_cost
from ..fit import fit_with_loss
from ..regressors import Regressors
from ..validation import MIN_SAMPLES_PER_PARAMETER, check_min_samples
from .gram import Normal, UNormal, check_condition, check_excited, loss_of, near_ties, solve_gram

FIXED_POINT = 4
LINEAR_SIGNAL = {K_TAU: "tau", K_V: "dq", OFFSET: None}  # None: the constant column


@dataclass(frozen=True)
class Term:
    """An effect in a model; ``shape`` None means "choose it from the effect's grid"."""

    effect: str
    shape: Mapping[str, float] | None = None

    def __post_init__(self) -> None:
        get_effect(self.effect)
        if self.shape is not None:
            object.__setattr__(self, "shape", {str(k): float(v) for k, v in self.shape.items()})

    def label(self) -> str:
        if not self.shape:
            return self.effect
        return f"{self.effect}({', '.join(f'{k}={v:.3g}' for k, v in self.shape.items())})"


@dataclass(frozen=True)
class ModelSpec:
    """Which coefficients a model has: ``linear`` (``k_tau``, ``k_v``) and effect ``terms``."""

    linear: tuple[str, ...] = (K_TAU, K_V)
    terms: tuple[Term, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "linear", tuple(self.linear))
        object.__setattr__(self, "terms", tuple(self.terms))
        for k in self.linear:
            if k not in LINEAR_SIGNAL:
                raise IdentificationError(f"linear coefficient '{k}': expected one of {list(LINEAR_SIGNAL)}")
        names = self.effect_names
        if len(set(names)) != len(names):
            raise IdentificationError(f"model terms {names}: expected each effect at most once")

    @property
    def effect_names(self) -> list[str]:
        return [t.effect for t in self.terms]

    def plus(self, term: Term) -> ModelSpec:
        return ModelSpec(self.linear, (*self.terms, term))

    def label(self) -> str:
        base = " + ".join(self.linear) if self.linear else "0"
        return " + ".join([base, *self.effect_names])

    @property
    def uses_u(self) -> bool:
        return any(get_effect(t.effect).uses_model for t in self.terms)


def linear_for(signals: Signals, offset: bool = False) -> tuple[str, ...]:
    """The linear coefficients the signals allow: ``k_tau`` if there is a torque, ``k_v`` always, and
    ``offset`` (a constant) if asked for."""
    return tuple(k for k, s in LINEAR_SIGNAL.items() if (s in signals if s is not None else offset))


def parse_spec(text: str | Sequence[str] | None, signals: Signals, offset: bool = False) -> ModelSpec:
    """A model from ``"paper"`` (k_tau, k_v), ``"coulomb"`` (paper + coulomb) or names joined by ``+``/``,``
    (e.g. ``"coulomb+deadzone"``; ``paper`` may appear and means nothing more; ``offset`` in the names, or
    ``offset=True``, adds the constant term to the base)."""
    parts = [] if text is None else text if not isinstance(text, str) else text.replace(",", "+").split("+")
    names = [p.strip() for p in parts if p.strip() and p.strip() != "paper"]
    offset = offset or OFFSET in names
    linear = linear_for(signals, offset)
    return ModelSpec(linear, tuple(Term(n) for n in names if n != OFFSET))


@dataclass(frozen=True, eq=False)
class FittedModel:
    """A fitted model: coefficients by name (``k_tau``, ``k_v``, effect names) and the loss used."""

    spec: ModelSpec
    coefficients: Mapping[str, float]
    loss: Loss = field(default_factory=Loss)

    def __post_init__(self) -> None:
        for t in self.spec.terms:
            if t.shape is None:
                raise IdentificationError(f"term '{t.effect}': a fitted model needs its shape")
        object.__setattr__(self, "coefficients", {k: float(v) for k, v in self.coefficients.items()})

    def u(self, signals: Signals) -> np.ndarray:
        """The model's servo error without the terms that read it [rad] (see :meth:`context`)."""
        return self.context(signals)["u"]

    def terms(self) -> ModelTerms:
        """The model as the actuator's evaluator reads it."""
        return ModelTerms(self.spec.linear, tuple((t.effect, t.shape) for t in self.spec.terms), self.coefficients)

    def context(self, signals: Signals) -> dict[str, np.ndarray]:
        """The model-dependent signals [rad] that some regressors read: ``u_tau = k_tau tau``,
        ``u_v = k_v dq`` and ``u``, the model's prediction without the terms that read ``u`` (the paper's
        ``k_tau tau + k_v dq`` plus friction-like terms: the position error the servo works with)."""
        return self.terms().context(signals)

    def predict(self, signals: Signals) -> np.ndarray:
        """Model output [rad] on ``signals``."""
        return self.terms().predict(signals)

    def describe(self) -> list[str]:
        lines = [f"{k} = {self.coefficients[k]:.6g}" for k in self.spec.linear]
        lines += [f"{t.label()}: {self.coefficients[t.effect]:.6g}" for t in self.spec.terms]
        return lines

    def to_motor_model(self, provenance: str, metrics: FitMetrics | None = None, target: str = SERVO_ERROR,
                       unit: str = SERVO_UNIT) -> MotorModel:
        """The motor-parameter entry of a model of ``target`` in ``unit`` (:meth:`MotorModel.from_terms`)."""
        return MotorModel.from_terms(self.terms(), self.loss, provenance, metrics, target=target, unit=unit)

    @classmethod
    def from_motor_model(cls, m: MotorModel) -> FittedModel:
        """The workbench form of a motor-parameter entry (``k_c`` is the ``coulomb`` term, plain sign)."""
        mt = m.terms()
        return cls(ModelSpec(mt.linear, tuple(Term(name, shape) for name, shape in mt.terms)), mt.coefficients, m.loss)


def design(signals: Signals, spec: ModelSpec, ctx: Mapping[str, np.ndarray] | None, cache: dict | None = None) -> tuple[
    list[str], np.ndarray, list[tuple[str, Mapping[str, float], slice]]
]:
    """Columns of ``spec`` (shapes fixed) with the model context ``ctx`` (``u``, ``u_tau``) for the terms
    that read it.

    Returns column names, the matrix and, per term, ``(effect, shape, column slice)``.
    """
    names = list(spec.linear)
    cols = [signals[LINEAR_SIGNAL[k]] if LINEAR_SIGNAL[k] is not None else np.ones(signals.n) for k in spec.linear]
    su = signals.with_columns(**ctx) if ctx is not None else signals
    slices = []
    for t in spec.terms:
        eff = get_effect(t.effect)
        if eff.uses_model:
            if ctx is None:
                raise IdentificationError(f"term '{t.effect}' reads u: expected the linear part of a model")
            m = eff.columns(su, t.shape)
        else:
            m = effect_columns(eff, signals, t.shape, cache)
        start = len(names)
        k = m.shape[1]
        names += [t.effect] if k == 1 else [f"{t.effect}#{i}" for i in range(k)]
        cols += list(m.T)
        slices.append((t.effect, t.shape, slice(start, start + k)))
    if not cols:
        raise IdentificationError("model has no coefficient: expected a torque or velocity column")
    return names, np.column_stack(cols), slices


def effect_columns(eff, signals: Signals, shape: Mapping[str, float], cache: dict | None) -> np.ndarray:
    """Columns of an effect that does not read ``u`` at ``shape``, kept in ``cache`` (if given) by effect and shape."""
    key = (eff.name, tuple(sorted(shape.items())))
    if cache is not None and key in cache:
        return cache[key]
    m = eff.columns(signals, shape)
    if cache is not None:
        cache[key] = m
    return m


def solve(
    names: list[str],
    matrix: np.ndarray,
    target: np.ndarray,
    loss: Loss,
    rows: np.ndarray | None,
    drop_unexcited: bool = False,
) -> np.ndarray:
    """Coefficients of ``matrix x ~ target`` on ``rows`` (all if None) for ``loss``; with ``drop_unexcited``,
    an effect column that is zero or constant on ``rows`` gets coefficient 0 instead of an error (a held-out
    block may hold every excitation of a rare effect).

    Least squares takes a fast path (normal equations of the column-scaled matrix, with the same refusals as
    :func:`~servotau.identification.problem.prepare_problem`: too few samples, a zero or constant
    column, dependent columns); the asymmetric loss goes through
    :func:`~servotau.identification.fit.fit_with_loss`.
    """
    a = matrix if rows is None else matrix[rows]
    b = target if rows is None else target[rows]
    if drop_unexcited:
        n = a.shape[0]
        ms = np.einsum("ij,ij->j", a, a) / n
        var = ms - (a.sum(axis=0) / n) ** 2
        keep = np.array([k in LINEAR_SIGNAL or (ms[j] > 0 and var[j] > 1e-20 * ms[j]) for j, k in enumerate(names)])
        if not keep.all():
            x = np.zeros(len(names))
            x[keep] = solve([k for k, ok in zip(names, keep, strict=True) if ok], matrix[:, keep], target, loss, rows)
            return x
    if loss.kind != "least_squares":  # eq. 8 is convex with the offset too: one exact Newton solve
        return fit_with_loss(Regressors(tuple(names), a), b, loss, constant=(OFFSET,)).x
    n, k = a.shape
    check_min_samples(n, MIN_SAMPLES_PER_PARAMETER * k, f"fit (coefficients {names})")
    ms = np.einsum("ij,ij->j", a, a) / n
    check_excited(names, ms, a.sum(axis=0) / n)
    scale = np.sqrt(ms)
    an = a / scale
    gram = an.T @ an
    check_condition(names, gram, n)
    return np.linalg.solve(gram, an.T @ b) / scale


def fold_coefficients(x: np.ndarray, spec: ModelSpec, slices) -> tuple[ModelSpec, dict[str, float]]:
    """Coefficients by name and the terms with their full shapes (multi-column effects folded)."""
    coefs = {k: float(x[i]) for i, k in enumerate(spec.linear)}
    terms = []
    for effect, shape, sl in slices:
        c, full = get_effect(effect).folded(x[sl], shape)
        coefs[effect] = c
        terms.append(Term(effect, full))
    return ModelSpec(spec.linear, tuple(terms)), coefs


def fit_spec(
    signals: Signals,
    target: np.ndarray,
    spec: ModelSpec,
    loss: Loss,
    rows: np.ndarray | None = None,
    cache: dict | None = None,
    drop_unexcited: bool = False,
) -> FittedModel:
    """Fit ``spec`` (every shape fixed) on ``rows`` with ``loss`` (``drop_unexcited``: see :func:`solve`)."""
    ctx = None
    if spec.uses_u:
        plain = ModelSpec(spec.linear, tuple(t for t in spec.terms if not get_effect(t.effect).uses_model))
        ctx = fit_spec(signals, target, plain, loss, rows, cache, drop_unexcited).context(signals)
    if not spec.uses_u:
        names, a, slices = design(signals, spec, None, cache)
        full, coefs = fold_coefficients(solve(names, a, target, loss, rows, drop_unexcited), spec, slices)
        return FittedModel(full, coefs, loss)
    best, best_err = None, np.inf
    normal = _u_normal(signals, target, spec, loss, rows, cache, drop_unexcited)
    for _ in range(FIXED_POINT):
        try:
            if normal is not None:
                names, x, slices = normal.solve(signals, ctx)
            else:
                names, a, slices = design(signals, spec, ctx, cache)
                x = solve(names, a, target, loss, rows, drop_unexcited)
        except IdentificationError:
            if best is None:
                raise
            break  # this round's u leaves a column unexcited (e.g. a threshold never reached): keep the best
        full, coefs = fold_coefficients(x, spec, slices)
        model = FittedModel(full, coefs, loss)
        ctx = model.context(signals)
        err = _loss_value(_predict_in(model, signals, ctx), target, loss, rows)
        if err < best_err:
            best, best_err = model, err
    return best


def _u_normal(signals, target, spec, loss, rows, cache, drop_unexcited) -> UNormal | None:
    """:class:`~.gram.UNormal` of the fixed point, or None where :func:`solve` is needed (another loss,
    ``drop_unexcited``, rows given by index, no column that ignores ``u``)."""
    if loss.kind != "least_squares" or drop_unexcited or (rows is not None and np.asarray(rows).dtype != bool):
        return None
    plain = ModelSpec(spec.linear, tuple(t for t in spec.terms if not get_effect(t.effect).uses_model))
    if not plain.linear and not plain.terms:
        return None
    names, a, slices = design(signals, plain, None, cache)
    return UNormal(spec, names, Normal(a, target, rows), slices)


def _predict_in(model: FittedModel, signals: Signals, ctx: Mapping[str, np.ndarray]) -> np.ndarray:
    """:meth:`FittedModel.predict` given the model's own context ``ctx`` (the same numbers, ``ctx`` not
    computed again)."""
    su = signals.with_columns(**ctx)
    out = ctx["u"].copy()
    for t in model.spec.terms:
        eff = get_effect(t.effect)
        if eff.uses_model:
            out += model.coefficients[t.effect] * eff.evaluate(su, t.shape)
    return out


def _loss_value(model: np.ndarray, target: np.ndarray, loss: Loss, rows: np.ndarray | None) -> float:
    if rows is not None:
        model, target = model[rows], target[rows]
    if loss.kind == "least_squares":
        return float(np.sum((model - target) ** 2))
    return asymmetric_cost(model - target, target, loss.w)


def resolve_shapes(
    signals: Signals,
    target: np.ndarray,
    spec: ModelSpec,
    loss: Loss,
    cache: dict | None = None,
    sweeps: int = 2,
    free: list[bool] | None = None,
) -> ModelSpec:
    """``spec`` with every shape-less term given the grid shape of least training loss.

    First each shape-less term in order, with the ones before it; then up to ``sweeps - 1`` passes of
    coordinate descent over the ``free`` terms (default: the shape-less ones), each term's shape chosen
    again with all the others in the model, until nothing changes (the result then hardly depends on the
    order of the terms). Other terms keep their shape.
    """
    free = [t.shape is None for t in spec.terms] if free is None else list(free)
    if len(free) != len(spec.terms):
        raise IdentificationError(f"free = {free}: expected one flag per term of {spec.effect_names}")
    memo: dict = {}  # the same term with the same others gives the same shape: not fitted again

    def best_shape(others: list[Term], effect: str) -> Term:
        key = (effect, tuple((o.effect, tuple(sorted(o.shape.items()))) for o in others))
        if key not in memo:
            try:
                memo[key] = _best_shape(signals, target, spec.linear, others, effect, loss, cache)
            except IdentificationError as exc:
                memo[key] = exc
        if isinstance(memo[key], IdentificationError):
            raise memo[key]
        return memo[key]

    done: list[Term] = []
    for t in spec.terms:
        fixed = t.shape is not None
        done.append(t if fixed else best_shape(list(done), t.effect))
    for _ in range(sweeps - 1):
        changed = False
        for i, t in enumerate(done):
            if not free[i]:
                continue
            others = done[:i] + done[i + 1 :]
            try:
                best = best_shape(others, t.effect)
            except IdentificationError:
                continue  # no other shape fits with these neighbours: keep the current one
            if best.shape != t.shape:
                done[i], changed = best, True
        if not changed:
            break
    return ModelSpec(spec.linear, tuple(done))


def _best_shape(signals, target, linear, others: list[Term], effect: str, loss: Loss, cache) -> Term:
    """The shape of ``effect``'s grid of least training loss, fitted with the terms ``others``."""
    best, err = None, np.inf
    failures = []
    eff = get_effect(effect)
    if loss.kind == "least_squares" and (linear or others) and not eff.uses_model \
            and not any(get_effect(t.effect).uses_model for t in others):
        return _best_shape_gram(signals, target, ModelSpec(linear, tuple(others)), eff, loss, cache)
    gsig = signals
    if eff.uses_model and callable(eff.grid):  # a data-dependent grid may read u: that of the fixed point's start
        plain = tuple(t for t in others if not get_effect(t.effect).uses_model)
        gsig = signals.with_columns(**fit_spec(signals, target, ModelSpec(linear, plain), loss,
                                               cache=cache).context(signals))
    for shape in eff.grid_for(gsig):
        trial = ModelSpec(linear, (*others, Term(effect, shape)))
        try:
            m = fit_spec(signals, target, trial, loss, cache=cache)
        except IdentificationError as exc:
            failures.append(str(exc))
            continue
        c = m.coefficients[effect]
        if not eff.admits(c):
            failures.append(f"shape {dict(shape)}: coefficient {c:.3g} outside {eff.coefficient_range}")
            continue
        e = _loss_value(m.predict(signals), target, loss, None)
        if e < err:
            best, err = Term(effect, m.spec.terms[-1].shape), e
    if best is None:
        raise IdentificationError(f"effect '{effect}': no shape of its grid could be fitted: {failures[0]}")
    return best


def _best_shape_gram(signals, target, base: ModelSpec, eff, loss: Loss, cache) -> Term:
    """:func:`_best_shape` by least squares when no term reads ``u``: the base's columns and products computed
    once, each shape's fit from the normal equations (:mod:`.gram`); near ties scored as :func:`_best_shape` does."""
    names0, a0, slices0 = design(signals, base, None, cache)
    ne = Normal(a0, target)
    tried, failures = [], []
    for shape in eff.grid_for(signals):
        term = Term(eff.name, shape)
        try:
            cols = effect_columns(eff, signals, term.shape, cache)
            k0, k = a0.shape[1], cols.shape[1]
            names = [*names0, *([eff.name] if k == 1 else [f"{eff.name}#{i}" for i in range(k)])]
            g, aty, colsum = ne.system(cols)
            x = solve_gram(names, g, aty, colsum, ne.n)
        except IdentificationError as exc:
            failures.append(str(exc))
            continue
        full, coefs = fold_coefficients(x, base.plus(term), [*slices0, (eff.name, term.shape, slice(k0, k0 + k))])
        c = coefs[eff.name]
        if not eff.admits(c):
            failures.append(f"shape {dict(shape)}: coefficient {c:.3g} outside {eff.coefficient_range}")
            continue
        tried.append((loss_of(x, g, aty, ne.yty), FittedModel(full, coefs, loss)))
    if not tried:
        raise IdentificationError(f"effect '{eff.name}': no shape of its grid could be fitted: {failures[0]}")
    ties = near_ties([t[0] for t in tried], ne.yty)
    if ties:
        tried = [(_loss_value(t[1].predict(signals), target, loss, None) if j in ties else np.inf, t[1])
                 for j, t in enumerate(tried)]
    best, err = None, np.inf
    for e, m in tried:
        if e < err:
            best, err = m, e
    return Term(eff.name, best.spec.terms[-1].shape)
