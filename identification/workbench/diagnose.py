"""Name the missing effect: rank every effect of the library by the held-out error it removes.

For each effect, each held-out block and each shape of the effect's grid, the current model plus the
effect is fitted on the other blocks with the same loss; the shape of least *training* error is kept
(nested selection), and the block is predicted. ``heldout_gain = 1 - E_with / E_base``, with ``E`` the
held-out error (RMS for least squares, ``sqrt`` of the mean asymmetric penalty otherwise): the fraction
of the held-out error the effect removes.

Non-parametric *probes* fit flexible functions of one family of signals to the current model's
residual, also on held-out blocks: bins of velocity; of torque by velocity sign; of ``u`` by velocity
sign; of position; a polynomial drift in time; lagged differences of ``u`` and ``q_des``; and the residual's
own past (``memory``: the residual ``h``, ``2 h`` and ``4 h`` earlier, ``h`` = ``MEMORY_HORIZON_S``). The named
effect is *partially explained* (e.g. a Stribeck velocity outside the grid) when its family's probe
removes much more than it does, or still removes ``REMAINING`` of the error (and a quarter of what the
effect did) once the effect is in the model. A probe that removes error when no effect does means
*unexplained* structure.

Verdict:

- ``missing_effect``: the best testable effect removes at least ``min_gain`` of the held-out error and
  helps in all held-out blocks but at most one.
- ``unexplained``: no effect does, but a probe removes at least ``PROBE_FACTOR * min_gain`` (probes
  have tens of free parameters; the memory probe catches a state the model lacks: where the joint crosses
  a dead band freely, its error depends on where it entered, a function of no present signal; ``deadzone``'s
  crossing form models it when the log has the command ``q_des``), or the
  largest 2 % of the held-out residuals carry more than half of the squared error and sit at the largest
  servo effort (the model fails at a current limit).
- ``no_missing_effect``: neither.

Effects that the data cannot test (see :mod:`~servotau.actuator.excitation`) are
ranked but never named: they are reported as untestable, not as absent.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from servotau.actuator import EXPERIMENTS, Effect, Excitation, Loss, excitation_report, get_effect, resolve_effects
from servotau.actuator.signals import delayed, ticks
from servotau.errors import IdentificationError

from .data import SMOOTH_TAU_S, Dataset
from .evaluate import Comparison, Fold, compare, error_of, folds_of
from .model import FittedModel, ModelSpec, Term, design, fit_spec, resolve_shapes, solve

log = logging.getLogger(__name__)

MIN_GAIN = 0.1
"""Default smallest held-out gain that names an effect (10 % of the held-out error)."""

PARTIAL = 0.75
"""An effect explaining less than this fraction of its family probe's gain is *partially explained*."""

REMAINING = 0.05
"""Held-out gain of the named effect's family probe, on the model with the effect, that flags it *partial*
(when it is also at least a quarter of the effect's own gain)."""

PROBE_FACTOR = 2.0
"""A probe (tens of free parameters) names ``unexplained`` structure from ``PROBE_FACTOR * min_gain`` on."""

MEMORY_HORIZON_S = SMOOTH_TAU_S
MEMORY_LAGS = (1, 2, 4)
"""The memory probe predicts the held-out residual from its own values ``k h`` earlier (``k`` in ``MEMORY_LAGS``,
``h`` = ``MEMORY_HORIZON_S`` [s], the torque's smoothing window): noise that the workbench's filters spread over
neighbouring samples is forgotten after ``h`` (the velocity's longer SG window carries ``k_v`` times a
differentiated encoder noise, orders smaller), so a residual still predictable ``h`` ahead has a state no term
models. Three coefficients fitted on the training blocks, the residual's past read as on-line (causal)."""

TAIL_FRACTION = 0.02
TAIL_SHARE = 0.5
"""``unexplained`` also when the ``TAIL_FRACTION`` largest held-out residuals carry more than ``TAIL_SHARE`` of
the squared error (about 0.14 for Gaussian residuals) and most of them sit at the largest servo effort: the
model fails at its limit (saturation). Residuals of real servos are heavy-tailed anyway (dead-band crossings
carry two thirds of the squared error of the simulated default servo), hence the second condition."""

VERDICTS = ("missing_effect", "no_missing_effect", "unexplained")


@dataclass(frozen=True)
class Candidate:
    """One effect's score against the current model.

    Attributes:
        effect: Effect name.
        heldout_gain: Fraction of the held-out error removed (can be negative: the effect over-fits).
        heldout_error: Held-out error with the effect.
        train_gain: Fraction of the training error removed (fitted on everything).
        fold_gains: Held-out gain per block.
        consistent: The effect helps in all held-out blocks but at most one.
        shape: Shape chosen on all samples (least training error).
        coefficient: Coefficient at that shape (all samples).
        at_grid_edge: The chosen shape is the first or last of a one-parameter grid: the true shape may
            lie outside.
        testable: The data excited the effect.
        reason: Why not testable (or why every fit failed).
        family: Probe family.
        explained: ``heldout_gain`` over the gain of its family's probe (None without probe).
        partial: Explains less than ``PARTIAL`` of what its family's probe finds, or (named effect) the
            probe still removes ``REMAINING``, and a quarter of the effect's gain, once the effect is in the model.
        remaining: For the named effect, the gain of its family's probe on the model with the effect.
    """

    effect: str
    heldout_gain: float
    heldout_error: float
    train_gain: float
    fold_gains: tuple[float, ...]
    consistent: bool
    shape: Mapping[str, float]
    coefficient: float
    at_grid_edge: bool
    testable: bool
    reason: str | None
    family: str
    explained: float | None = None
    partial: bool = False
    remaining: float | None = None

    def to_dict(self) -> dict:
        return {
            "effect": self.effect,
            "heldout_gain": _r(self.heldout_gain),
            "heldout_error": _r(self.heldout_error),
            "train_gain": _r(self.train_gain),
            "fold_gains": [_r(g) for g in self.fold_gains],
            "consistent": self.consistent,
            "shape": {k: _r(v) for k, v in self.shape.items()},
            "coefficient": _r(self.coefficient),
            "at_grid_edge": self.at_grid_edge,
            "testable": self.testable,
            "reason": self.reason,
            "family": self.family,
            "explained": None if self.explained is None else _r(self.explained),
            "partial": self.partial,
            "remaining": None if self.remaining is None else _r(self.remaining),
        }


@dataclass(frozen=True)
class Confusion:
    """Two effects the data cannot tell apart well, and the experiment that would."""

    effects: tuple[str, str]
    gains: tuple[float, float]
    correlation: float  # of their columns once the current model's columns are projected out
    experiment: str

    def to_dict(self) -> dict:
        return {"effects": list(self.effects), "gains": [_r(g) for g in self.gains],
                "correlation": _r(self.correlation), "experiment": self.experiment}


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`diagnose`.

    Attributes:
        verdict: One of :data:`VERDICTS`.
        base: The current model against the measurement (training and held-out).
        ranking: Every effect, testable ones first, by held-out gain.
        probes: Held-out gain of each non-parametric probe family.
        excitation: What the data exercised.
        min_gain: Threshold used.
        confusion: The top two effects if they are a documented confusable pair (or nearly tie).
        message: One-paragraph human summary.
    """

    verdict: str
    base: Comparison
    ranking: tuple[Candidate, ...]
    probes: Mapping[str, float]
    excitation: Excitation
    min_gain: float
    confusion: Confusion | None = None
    message: str = ""
    experiments: Mapping[str, str] = field(default_factory=dict)
    tail_share: float = 0.0

    @property
    def top(self) -> Candidate | None:
        return self.ranking[0] if self.ranking and self.ranking[0].testable else None

    @property
    def runner_up(self) -> Candidate | None:
        tested = [c for c in self.ranking if c.testable]
        return tested[1] if len(tested) > 1 else None

    def candidate(self, effect: str) -> Candidate:
        for c in self.ranking:
            if c.effect == effect:
                return c
        names = [c.effect for c in self.ranking]
        raise IdentificationError(f"effect '{effect}' was not ranked: expected one of {names}")

    def rank_of(self, effect: str) -> int:
        """1-based rank among testable effects (0 if untestable or not ranked)."""
        tested = [c.effect for c in self.ranking if c.testable]
        return tested.index(effect) + 1 if effect in tested else 0

    def to_dict(self) -> dict:
        return {
            "verdict": self.verdict,
            "message": self.message,
            "model": self.base.model.spec.label(),
            "min_gain": self.min_gain,
            "ranking": [c.to_dict() for c in self.ranking],
            "runner_up": None if self.runner_up is None else self.runner_up.effect,
            "probes": {k: _r(v) for k, v in self.probes.items()},
            "confusion": None if self.confusion is None else self.confusion.to_dict(),
            "untestable": {c.effect: c.reason for c in self.ranking if not c.testable},
            "experiments": dict(self.experiments),
            "tail_share": _r(self.tail_share),
            "train": self.base.train.to_dict(),
            "heldout": None if self.base.heldout is None else self.base.heldout.to_dict(),
            "excitation": self.excitation.to_dict(),
        }


def _r(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(f"{x:.6g}")


# -- probes --------------------------------------------------------------------------------------------
def _onehot(index: np.ndarray, k: int) -> np.ndarray:
    m = np.zeros((len(index), k))
    m[np.arange(len(index)), index] = 1.0
    return m


def _quantile_bins(x: np.ndarray, k: int) -> np.ndarray:
    edges = np.unique(np.quantile(x, np.linspace(0, 1, k + 1)[1:-1]))
    return np.searchsorted(edges, x)


def _velocity_class(dq: np.ndarray, v: float = 0.01) -> np.ndarray:
    return np.where(dq > v, 2, np.where(dq < -v, 0, 1))


def _by_class(x: np.ndarray, cls: np.ndarray, k: int) -> np.ndarray:
    b = _quantile_bins(x, k)
    return _onehot(cls * (b.max() + 1) + b, 3 * (b.max() + 1))


def probe_columns(signals, u: np.ndarray) -> dict[str, np.ndarray]:
    """Flexible regressors of each signal family (columns without any sample dropped)."""
    dq = signals["dq"]
    cls = _velocity_class(dq)
    out = {"velocity": _onehot(_quantile_bins(dq, 24), 24)}
    if "tau" in signals:
        out["torque"] = _by_class(signals["tau"], cls, 12)
    out["servo_error"] = _by_class(u, cls, 12)
    if "q" in signals:
        q = signals["q"]
        span = float(np.ptp(q))
        if span > 0:
            idx = np.minimum(((q - q.min()) / span * 64).astype(int), 63)
            out["position"] = _onehot(idx, 64)
    if "t" in signals:
        t = signals["t"]
        x = (t - t.mean()) / (np.ptp(t) or 1.0)
        s = np.tanh(dq / 0.01)
        out["time"] = np.column_stack([x, x * x, x * dq, x * x * dq, x * s, x * x * s])
    if signals.dt is not None:
        cols = []
        for lag in (0.002, 0.005, 0.01, 0.02, 0.04):
            k = ticks(lag, signals.dt)
            cols += [delayed(u, k) - u, np.concatenate([u[k:], np.full(k, u[-1])]) - u]
            if "q_des" in signals:
                cols.append(signals["q_des"] - delayed(signals["q_des"], k))
        if "ddq" in signals:
            cols.append(signals["ddq"])
        out["dynamics"] = np.column_stack(cols)
    return {k: m[:, np.any(m != 0, axis=0)] for k, m in out.items()}


def _ridge(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    scale = np.sqrt(np.mean(a * a, axis=0))
    scale[scale == 0] = 1.0
    an = a / scale
    g = an.T @ an
    g[np.diag_indices_from(g)] += 1e-6 * np.trace(g) / len(g)
    return np.linalg.solve(g, an.T @ b) / scale


# -- ranking -------------------------------------------------------------------------------------------
@dataclass(eq=False)
class _FoldBase:
    fold: Fold
    ctx: dict
    names: list[str]
    a: np.ndarray
    pred: np.ndarray  # base prediction on all rows, fitted on the fold's training rows


def _base_per_fold(ds: Dataset, spec: ModelSpec, loss: Loss, folds: list[Fold], cache: dict) -> list[_FoldBase]:
    out = []
    for f in folds:
        m = fit_spec(ds.signals, ds.target, spec, loss, rows=f.train, cache=cache, drop_unexcited=True)
        ctx = m.context(ds.signals)
        names, a, _ = design(ds.signals, spec, ctx, cache)
        x = solve(names, a, ds.target, loss, f.train, drop_unexcited=True)
        out.append(_FoldBase(f, ctx, names, a, a @ x))
    return out


def _effect_columns(effect: Effect, signals, ctx: dict, shape, cache: dict) -> np.ndarray:
    if effect.uses_model:
        return effect.columns(signals.with_columns(**ctx), shape)
    key = (effect.name, tuple(sorted(shape.items())))
    if key not in cache:
        cache[key] = effect.columns(signals, shape)
    return cache[key]


def _score_effect(
    ds: Dataset, effect: Effect, bases: list[_FoldBase], loss: Loss, cache: dict
) -> tuple[np.ndarray, list[str]]:
    """Held-out prediction of base + effect (nested shape choice per block), and fit failures. Shapes whose
    coefficient the effect's physics does not allow (``Effect.coefficient_range``) are not chosen; a block
    left with none keeps the base model's prediction (the effect adds nothing there)."""
    y = ds.target
    pred = np.full(ds.n, np.nan)
    failures: list[str] = []
    for b in bases:
        best, best_err, rejected = None, np.inf, False
        for shape in effect.grid_for(ds.signals.with_columns(**b.ctx)):
            try:
                cols = _effect_columns(effect, ds.signals, b.ctx, shape, cache)
                a = np.column_stack([b.a, cols])
                names = [*b.names, *(f"{effect.name}#{i}" for i in range(cols.shape[1]))]
                x = solve(names, a, y, loss, b.fold.train)
            except IdentificationError as exc:
                failures.append(str(exc))
                continue
            if cols.shape[1] == 1 and not effect.admits(x[-1]):
                rejected = True  # not this effect: a generic correction of the other sign or size
                continue
            p = a @ x
            tr = b.fold.train
            err = error_of(y[tr] - p[tr], y[tr], loss)
            if err < best_err:
                best, best_err = p, err
        if best is None and rejected:
            best = b.pred  # no shape with a coefficient the physics allows: the block keeps the base model
        if best is None:
            return pred, failures
        pred[b.fold.test] = best[b.fold.test]
    return pred, failures


def _fold_errors(y: np.ndarray, pred: np.ndarray, folds: list[Fold], loss: Loss) -> np.ndarray:
    return np.array([error_of(y[f.test] - pred[f.test], y[f.test], loss) for f in folds])


def _full_fit(ds: Dataset, spec: ModelSpec, effect: Effect, loss: Loss, cache: dict) -> tuple[FittedModel, float]:
    """Base + effect on all samples at the shape of least training error; its training error."""
    resolved = resolve_shapes(ds.signals, ds.target, spec.plus(Term(effect.name)), loss, cache)
    m = fit_spec(ds.signals, ds.target, resolved, loss, cache=cache)
    return m, error_of(ds.target - m.predict(ds.signals), ds.target, loss)


def _grid_edge(effect: Effect, shape: Mapping[str, float], signals) -> bool:
    if callable(effect.grid):
        return False
    grid = effect.grid_for(signals)
    keys = [k for k in grid[0] if len({g[k] for g in grid}) > 1]
    if len(keys) != 1 or len(grid) < 3:
        return False
    values = sorted({g[keys[0]] for g in grid})
    return shape.get(keys[0]) in (values[0], values[-1])


def _orthogonal_correlation(ds: Dataset, spec: ModelSpec, base: FittedModel, a: str, b: str, shapes) -> float:
    ctx = base.context(ds.signals)
    names, m, _ = design(ds.signals, spec, ctx)
    su = ds.signals.with_columns(**ctx)
    ca = get_effect(a).evaluate(su, shapes[a])
    cb = get_effect(b).evaluate(su, shapes[b])
    q, _ = np.linalg.qr(m)
    ra, rb = ca - q @ (q.T @ ca), cb - q @ (q.T @ cb)
    den = float(np.linalg.norm(ra) * np.linalg.norm(rb))
    return float(ra @ rb / den) if den > 0 else float("nan")


def diagnose(
    ds: Dataset,
    spec: ModelSpec,
    loss: Loss | None = None,
    *,
    effects: Iterable[str] | None = None,
    folds: list[Fold] | None = None,
    min_gain: float = MIN_GAIN,
    cache: dict | None = None,
    progress: Callable[[str], None] | None = None,
) -> Diagnosis:
    """Rank the effects missing from ``spec`` on ``ds`` and give the verdict (see the module doc).

    Args:
        ds: The data.
        spec: The current model (terms without a shape get the best shape of their grid).
        loss: Loss of every fit (default least squares).
        effects: Effects to rank (default every registered effect not in ``spec``).
        folds: Held-out blocks (default :func:`~servotau.identification.workbench.evaluate.folds_of`).
        min_gain: Smallest held-out gain that names an effect, in (0, 1).
        cache: Column cache shared between calls on the same data.
        progress: Called with a short message per effect.
    """
    if not 0.0 < min_gain < 1.0:
        raise IdentificationError(f"min_gain = {min_gain!r}: expected a fraction in (0, 1)")
    loss = loss or Loss.least_squares()
    cache = {} if cache is None else cache
    folds = folds or folds_of(ds)
    spec = resolve_shapes(ds.signals, ds.target, spec, loss, cache)
    base = compare(ds, spec, loss, folds=folds, cache=cache)
    y = ds.target
    exc = excitation_report(ds.signals)
    bases = _base_per_fold(ds, spec, loss, folds, cache)
    base_pred = np.full(ds.n, np.nan)
    for b in bases:
        base_pred[b.fold.test] = b.pred[b.fold.test]
    e0 = error_of(y - base_pred, y, loss)
    e0_folds = _fold_errors(y, base_pred, folds, loss)
    train0 = base.train.error
    todo = [e for e in resolve_effects(effects) if e.name not in spec.effect_names]
    probes = _probe_gains(ds, bases, base.model, loss, e0)
    ranking = []
    for i, eff in enumerate(todo):
        if progress:
            progress(f"[{i + 1}/{len(todo)}] {eff.name}")
        missing = [s for s in eff.signals if s not in ("u", "u_tau", "u_v") and s not in ds.signals]
        if missing:
            ranking.append(_untestable(eff, f"needs signal(s) {missing}: not in the log"))
            continue
        reason = eff.needs(exc) if eff.needs is not None else None
        pred, failures = _score_effect(ds, eff, bases, loss, cache)
        if np.isnan(pred).any():
            ranking.append(_untestable(eff, f"no shape could be fitted: {failures[0] if failures else '?'}"))
            continue
        e1 = error_of(y - pred, y, loss)
        fold_gains = 1.0 - _fold_errors(y, pred, folds, loss) / np.where(e0_folds > 0, e0_folds, 1.0)
        try:
            full, e_train = _full_fit(ds, spec, eff, loss, cache)
            shape, coef = full.spec.terms[-1].shape, full.coefficients[eff.name]
        except IdentificationError as exc_:
            shape, coef, e_train = {}, float("nan"), train0
            failures.append(str(exc_))
        gain = 1.0 - e1 / e0 if e0 > 0 else 0.0
        probe = probes.get(eff.family)
        explained = None if probe is None or probe <= 0 else min(gain / probe, 1.0) if gain > 0 else 0.0
        ranking.append(Candidate(
            effect=eff.name,
            heldout_gain=gain,
            heldout_error=e1,
            train_gain=1.0 - e_train / train0 if train0 > 0 else 0.0,
            fold_gains=tuple(float(g) for g in fold_gains),
            consistent=bool(np.count_nonzero(fold_gains > 0) >= len(folds) - 1),
            shape=dict(shape),
            coefficient=coef,
            at_grid_edge=_grid_edge(eff, shape, ds.signals),
            testable=reason is None,
            reason=reason,
            family=eff.family,
            explained=explained,
            partial=bool(explained is not None and explained < PARTIAL and probe - gain > 0.05),
        ))
    ranking.sort(key=lambda c: (not c.testable, -c.heldout_gain if math.isfinite(c.heldout_gain) else math.inf))
    top = ranking[0] if ranking and ranking[0].testable else None
    if top is not None and top.heldout_gain >= min_gain and top.consistent and top.family in probes:
        try:
            with_top = spec.plus(Term(top.effect, top.shape))
            b2 = _base_per_fold(ds, with_top, loss, folds, cache)
            p2 = np.full(ds.n, np.nan)
            for b in b2:
                p2[b.fold.test] = b.pred[b.fold.test]
            fitted = fit_spec(ds.signals, y, with_top, loss, cache=cache)
            rem = _probe_gains(ds, b2, fitted, loss, error_of(y - p2, y, loss), only=top.family)[top.family]
            partial = top.partial or (rem >= REMAINING and rem >= 0.25 * top.heldout_gain)
            ranking[0] = replace(top, remaining=rem, partial=partial)
        except IdentificationError:
            pass
    return _verdict(ds, spec, base, tuple(ranking), probes, exc, min_gain)


def _untestable(eff: Effect, reason: str) -> Candidate:
    nan = float("nan")
    return Candidate(eff.name, nan, nan, nan, (), False, {}, nan, False, False, reason, eff.family)


def _probe_gains(
    ds: Dataset, bases: list[_FoldBase], base: FittedModel, loss: Loss, e0: float, only: str | None = None
) -> dict[str, float]:
    y = ds.target
    cols = probe_columns(ds.signals, base.u(ds.signals))
    out = {}
    for family, p in cols.items():
        if p.shape[1] == 0 or (only is not None and family != only):
            continue
        pred = np.full(ds.n, np.nan)
        for b in bases:
            tr, te = b.fold.train, b.fold.test
            beta = _ridge(p[tr], y[tr] - b.pred[tr])
            pred[te] = b.pred[te] + p[te] @ beta
        out[family] = 1.0 - error_of(y - pred, y, loss) / e0 if e0 > 0 else 0.0
    if ds.signals.dt is not None and only in (None, "memory"):
        out["memory"] = _memory_gain(ds, bases, loss, e0)
    return out


def _memory_gain(ds: Dataset, bases: list[_FoldBase], loss: Loss, e0: float) -> float:
    """Held-out gain of predicting the residual from its own past (:data:`MEMORY_LAGS` x :data:`MEMORY_HORIZON_S`):
    per block, the residual of the model fitted on the other blocks, its past read causally."""
    y = ds.target
    h = ticks(MEMORY_HORIZON_S, ds.signals.dt)
    pred = np.full(ds.n, np.nan)
    for b in bases:
        tr, te = b.fold.train, b.fold.test
        r = y - b.pred
        p = np.column_stack([delayed(r, k * h) for k in MEMORY_LAGS])
        pred[te] = b.pred[te] + p[te] @ _ridge(p[tr], r[tr])
    return 1.0 - error_of(y - pred, y, loss) / e0 if e0 > 0 else 0.0


def _verdict(ds, spec, base, ranking, probes, exc, min_gain) -> Diagnosis:
    named = [c for c in ranking if c.testable and c.heldout_gain >= min_gain and c.consistent]
    experiments = {}
    confusion = None
    if named:
        top = named[0]
        verdict = "missing_effect"
        tested = [c for c in ranking if c.testable]
        second = tested[1] if len(tested) > 1 else None
        eff = get_effect(top.effect)
        for other in eff.confusable:
            key = frozenset((top.effect, other))
            if key in EXPERIMENTS:
                experiments[other] = EXPERIMENTS[key]
        if second is not None and second.heldout_gain > 0 and (
            second.effect in eff.confusable or top.effect in get_effect(second.effect).confusable
            or second.heldout_gain >= 0.9 * top.heldout_gain
        ) and second.heldout_gain >= 0.5 * top.heldout_gain:
            corr = _orthogonal_correlation(ds, spec, base.model, top.effect, second.effect,
                                           {top.effect: top.shape, second.effect: second.shape})
            text = EXPERIMENTS.get(frozenset((top.effect, second.effect)),
                                   "excite the two effects separately (see docs/workbench.md, effect library)")
            confusion = Confusion((top.effect, second.effect), (top.heldout_gain, second.heldout_gain), corr, text)
        shape = ", ".join(f"{k} = {v:.3g}" for k, v in top.shape.items())
        message = (f"missing effect: {top.effect}" + (f" ({shape})" if shape else "")
                   + f" removes {100 * top.heldout_gain:.0f} % of the held-out error")
        if top.partial:
            message += (f"; partially explained: a free function of its signals ({top.family}) removes "
                        f"{100 * probes[top.family]:.0f} %"
                        + (f", and still {100 * top.remaining:.0f} % with the effect in the model"
                           if top.remaining is not None else "")
                        + ": the shape may lie outside the grid")
        if second is not None:
            message += f"; runner-up {second.effect} ({100 * second.heldout_gain:.0f} %)"
        if confusion is not None:
            message += f"; to separate them: {confusion.experiment}"
    else:
        # a function of the present signals says which; the memory probe (any smooth residual) only that some remains
        best_probe = max(((k, v) for k, v in probes.items() if k != "memory"), key=lambda kv: kv[1],
                         default=(None, 0.0))
        memory = probes.get("memory", 0.0)
        tail, where = _tail(ds, base)
        no_effect = f"unexplained: no effect of the library removes {100 * min_gain:.0f} % of the held-out error, "
        if best_probe[0] is not None and best_probe[1] >= PROBE_FACTOR * min_gain:
            verdict = "unexplained"
            message = no_effect + (f"but a free function of the {best_probe[0]} signals removes "
                                   f"{100 * best_probe[1]:.0f} %")
        elif memory >= PROBE_FACTOR * min_gain:
            verdict = "unexplained"
            message = no_effect + (f"but the residual's own past ({1e3 * MEMORY_HORIZON_S:.0f} ms and more earlier) "
                                   f"predicts {100 * memory:.0f} % of it: a state no term models (e.g. a dead band "
                                   "crossed freely in a log without the command: the error depends on where the "
                                   "joint entered)")
        elif tail >= TAIL_SHARE and where:
            verdict = "unexplained"
            message = (f"unexplained: {100 * tail:.0f} % of the squared held-out error sits in "
                       f"{100 * TAIL_FRACTION:.0f} % of the samples{where}; no effect of the library removes "
                       f"{100 * min_gain:.0f} %")
        else:
            verdict = "no_missing_effect"
            best = next((c for c in ranking if c.testable), None)
            message = "no missing effect: no effect removes " + f"{100 * min_gain:.0f} % of the held-out error"
            if best is not None:
                message += f" (best: {best.effect}, {100 * best.heldout_gain:.1f} %)"
    untestable = [c.effect for c in ranking if not c.testable]
    if untestable:
        message += f"; untestable on this data: {', '.join(untestable)}"
    return Diagnosis(verdict, base, ranking, probes, exc, min_gain, confusion, message, experiments, _tail(ds, base)[0])


def _tail(ds: Dataset, base: Comparison) -> tuple[float, str]:
    """Share of the squared held-out error in the largest ``TAIL_FRACTION`` of the residuals, and where."""
    r = base.residual
    k = max(1, int(TAIL_FRACTION * len(r)))
    idx = np.argsort(np.abs(r))[-k:]
    share = float(np.sum(r[idx] ** 2) / np.sum(r * r)) if np.any(r) else 0.0
    ctx = base.model.context(ds.signals)
    m = np.abs(ctx["u"] - 0.67 * ctx["u_v"])
    top = m >= np.quantile(m, 0.95)
    where = ""
    if top[idx].mean() > 0.5:
        where = (f" where the servo effort |u| is in its top 5 % ({100 * top[idx].mean():.0f} % of them): a current "
                 "limit (saturation) that no model of the torque can follow")
    return share, where
