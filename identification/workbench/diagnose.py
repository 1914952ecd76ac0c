"""Name the missing effect: rank every effect of the library by the held-out error it removes.

For each effect, each held-out block and each shape of the effect's grid, the current model plus the effect is
fitted on the other blocks with the same loss; the shape of least *training* error is kept (nested selection),
and the block is predicted. ``heldout_gain = 1 - E_with / E_base``, with ``E`` the held-out error (RMS for least
squares, ``sqrt`` of the mean asymmetric penalty otherwise): the fraction of the held-out error the effect removes.

Non-parametric *probes* fit flexible functions of one family of signals to the current model's
residual, also on held-out blocks: bins of velocity; of torque by velocity sign; of ``u`` by velocity sign; of
position; a polynomial drift in time; lagged differences of ``u`` and ``q_des``; and the residual's own past
(``memory``: the residual ``h``, ``2 h`` and ``4 h`` earlier, ``h`` = ``MEMORY_HORIZON_S``). The named effect is
*partially explained* (e.g. a Stribeck velocity outside the grid) when its family's probe removes much more than
it does, or still removes ``REMAINING`` of the error (and a quarter of what the effect did) once the effect is in
the model. A probe that removes error when no effect does means *unexplained* structure.

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

The workbench never reports its own preprocessing error as a physical effect: when ``dq`` was
differentiated here (not the log's own), a lag-like effect (family ``dynamics``: delay, motor lag,
elastic, backlash) that would be named is re-scored with less biased velocities (:func:`~.checks.derivative_checks`:
over half the window, and a cubic fit over the same window); if its held-out gain with either falls below
``min_gain`` it is not named but reported untestable, "cannot tell: may be the differentiation's error", and the
next effect is considered; likewise with the torque smoothed by a quartic fit (:func:`~.checks.smoothing_check`:
a long order-2 smoothing of a noisy torque errs where the torque bends, "may be the torque smoothing's error").
A function of the velocity (family ``velocity``: Coulomb, Stribeck, power-law viscous, Dahl, LuGre friction,
stiction) is re-scored with the less biased velocities too: it can fit the derivative's amplitude error where the
motion bends (``CHECKED``).
On a servo-error log whose model has no constant offset, such an effect is also re-scored with one: a constant
error (an encoder's zero, a dead zone under a load of one sign) biases ``k_tau``, which lag-like terms fit (and a
function of the position, family ``position``, on a joint turning one way): "cannot tell: may be a constant
error", and the message says to rerun with the offset. Whatever the verdict, the message says what an offset alone
would remove when that is at least ``min_gain`` (:func:`~.checks.constant_error`), unless an effect already lost
its gain to the offset (the message then says to add it).

Effects that the data cannot test (see :mod:`~servotau.actuator.excitation`) are ranked but never named: they are
reported as untestable, not as absent. A reason that is only a look-alike's (``Effect.lookalike_needs``) does not
hold where the effect would be named first and its look-alikes remove little (:func:`~.verdict.lookalikes_apart`).
Nor is an effect named (or a probe counted) that removes no more error than the log's noise floor
(:mod:`.resolution`).

With ``missing_effect``, every other testable effect is scored again over the model with the named one (same
blocks, checks and floor): the best, if the verdict could name it there, is the next to add
(:attr:`~.verdict.Diagnosis.then`). Two effects hidden together often rank as the named one and its look-alikes
over the base model; the second shows once the first is in (:attr:`~.verdict.Diagnosis.shortlist`). Of two effects
tied within ``TIE`` (:func:`~.verdict.tied_rival`), the one whose next effect leaves the smaller error is named.

This module ranks the effects; the probes are in :mod:`.probes`, the result types and the verdict in
:mod:`.verdict`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import replace

import numpy as np

from servotau.actuator import Effect, Loss, resolve_effects
from servotau.actuator.excitation import units_plausible
from servotau.actuator.terms import K_TAU
from servotau.errors import IdentificationError

from ..data.folds import Fold, folds_of
from .checks import (
    CONSTANT_ERROR,
    DIFFERENTIATION,
    OFFSET_ADVICE,
    SMOOTHING,
    constant_error,
    offset_spec,
    preprocessing_checks,
)
from .data import Dataset, excitation_of
from .evaluate import compare, error_of
from .gram import Normal, loss_of, near_ties
from .model import FittedModel, ModelSpec, Term, effect_columns, fit_spec, resolve_shapes, solve, solve_gram
from .probes import FoldBase, base_per_fold, heldout_prediction, probe_gains
from .resolution import error_floor, probes_within_resolution, removed_error, within_resolution
from .verdict import (
    OFFSET_PROBE,
    Candidate,
    Confusion,
    Diagnosis,
    at_grid_edge,
    lookalikes_apart,
    nameable,
    recheck_probes,
    tied_rival,
    verdict_of,
)

__all__ = ["MIN_GAIN", "PARTIAL", "REMAINING", "Candidate", "Confusion", "Diagnosis", "diagnose"]

log = logging.getLogger(__name__)

MIN_GAIN = 0.1
"""Default smallest held-out gain that names an effect (10 % of the held-out error)."""

PARTIAL = 0.75
"""An effect explaining less than this fraction of its family probe's gain is *partially explained*."""

REMAINING = 0.05
"""Held-out gain of the named effect's family probe, on the model with the effect, that flags it *partial*
(when it is also at least a quarter of the effect's own gain)."""


CHECKED = {"dynamics": (DIFFERENTIATION, SMOOTHING, CONSTANT_ERROR), "velocity": (DIFFERENTIATION,),
           "position": (CONSTANT_ERROR,)}
"""The checks an effect of each family must survive to be named (:func:`_checked`). Lag-like effects fit the
derivative's and the smoothing's lag and a constant error; functions of the velocity (friction) fit the derivative's
amplitude error where the motion bends (an order-2 derivative's window spans the servo's transients at coarse
sample periods); a function of the position (cogging) fits part of a constant error where the joint turns one way
(the position then follows time)."""

_LS = Loss.least_squares()


def _effect_columns(effect: Effect, signals, ctx: dict, shape, cache: dict) -> np.ndarray:
    if effect.uses_model:
        return effect.columns(signals.with_columns(**ctx), shape)
    return effect_columns(effect, signals, shape, cache)


def _score_effect(
    ds: Dataset, effect: Effect, bases: list[FoldBase], loss: Loss, cache: dict
) -> tuple[np.ndarray, list[str]]:
    """Held-out prediction of base + effect (nested shape choice per block), and fit failures. Shapes whose
    coefficient the effect's physics does not allow (``Effect.coefficient_range``) are not chosen; a block
    left with none keeps the base model's prediction (the effect adds nothing there). Least squares is solved
    from cross products shared by the blocks (:mod:`.gram`)."""
    y = ds.target
    pred = np.full(ds.n, np.nan)
    failures: list[str] = []
    fit = _GramFit(bases, y) if loss.kind == "least_squares" else None
    for i, b in enumerate(bases):
        tried, rejected = [], False  # tried: (training error, coefficients, columns)
        for shape in effect.grid_for(ds.signals.with_columns(**b.ctx)):
            try:
                cols = _effect_columns(effect, ds.signals, b.ctx, shape, cache)
                names = [*b.names, *(f"{effect.name}#{j}" for j in range(cols.shape[1]))]
                if fit is not None:
                    x, err = fit(i, names, cols)
                else:
                    a = np.column_stack([b.a, cols])
                    x = solve(names, a, y, loss, b.fold.train)
                    tr = b.fold.train
                    err = error_of(y[tr] - (a @ x)[tr], y[tr], loss)
            except IdentificationError as exc:
                failures.append(str(exc))
                continue
            if cols.shape[1] == 1 and not effect.admits(x[-1]):
                rejected = True  # not this effect: a generic correction of the other sign or size
                continue
            tried.append((err, x, cols))
        best = fit.best(i, tried) if fit is not None else _least(tried)
        if best is None:
            if not rejected:
                return pred, failures
            pred[b.fold.test] = b.pred[b.fold.test]  # no shape the physics allows: the block keeps the base model
            continue
        _, x, cols = best
        te = b.fold.test
        k = b.a.shape[1]
        pred[te] = b.a[te] @ x[:k] + cols[te] @ x[k:]
    return pred, failures


def _least(tried: list) -> tuple | None:
    """The first entry of least error (errors that are not numbers never win)."""
    best, best_err = None, np.inf
    for t in tried:
        if t[0] < best_err:
            best, best_err = t, t[0]
    return best


class _GramFit:
    """Least-squares fits of each block's base columns plus candidate columns on the block's training rows,
    from the normal equations (:mod:`.gram`)."""

    def __init__(self, bases: list[FoldBase], y: np.ndarray):
        self.y = y
        self.normal = [Normal(b.a, y, b.fold.train) for b in bases]

    def __call__(self, i: int, names: list[str], cols: np.ndarray) -> tuple[np.ndarray, float]:
        """Coefficients and training error (RMS, from the normal equations) of block ``i``."""
        ne = self.normal[i]
        g, aty, colsum = ne.system(cols)
        x = solve_gram(names, g, aty, colsum, ne.n)
        return x, float(np.sqrt(max(loss_of(x, g, aty, ne.yty), 0.0) / ne.n))

    def best(self, i: int, tried: list) -> tuple | None:
        """:func:`_least`, near ties ordered by their training residuals (the Gram errors lose digits)."""
        ne = self.normal[i]
        ties = near_ties([t[0] ** 2 * ne.n for t in tried], ne.yty)
        if ties:
            tr = ne.mask
            y, a = self.y[tr], ne.base[tr]
            k = a.shape[1]
            tried = [(error_of(y - (a @ t[1][:k] + t[2][tr] @ t[1][k:]), y, _LS), t[1], t[2])
                     if j in ties else (np.inf, t[1], t[2]) for j, t in enumerate(tried)]
        return _least(tried)


def _fold_errors(y: np.ndarray, pred: np.ndarray, folds: list[Fold], loss: Loss) -> np.ndarray:
    return np.array([error_of(y[f.test] - pred[f.test], y[f.test], loss) for f in folds])


def _heldout_gain(y: np.ndarray, pred: np.ndarray, e0: float, e0_folds: np.ndarray, folds: list[Fold], loss: Loss
                  ) -> tuple[float, float, tuple[float, ...], bool]:
    """Of a held-out prediction against the model's (error ``e0``, per block ``e0_folds``): its error, the gain
    ``1 - e1 / e0``, the gain per block, and whether it helps in every block but at most one."""
    e1 = error_of(y - pred, y, loss)
    fold_gains = 1.0 - _fold_errors(y, pred, folds, loss) / np.where(e0_folds > 0, e0_folds, 1.0)
    consistent = bool(np.count_nonzero(fold_gains > 0) >= len(folds) - 1)
    return e1, 1.0 - e1 / e0 if e0 > 0 else 0.0, tuple(float(g) for g in fold_gains), consistent


def _full_fit(ds: Dataset, spec: ModelSpec, effect: Effect, loss: Loss, cache: dict) -> tuple[FittedModel, float]:
    """Base + effect on all samples at the shape of least training error; its training error."""
    resolved = resolve_shapes(ds.signals, ds.target, spec.plus(Term(effect.name)), loss, cache)
    m = fit_spec(ds.signals, ds.target, resolved, loss, cache=cache)
    return m, error_of(ds.target - m.predict(ds.signals), ds.target, loss)


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
    next_effect: bool = True,
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
        next_effect: With ``missing_effect``, also score every other effect over the model with the named one
            (:attr:`Diagnosis.then`, about a second grid pass); the greedy ladder, which diagnoses that model
            next anyway, does not.
    """
    if not 0.0 < min_gain < 1.0:
        raise IdentificationError(f"min_gain = {min_gain!r}: expected a fraction in (0, 1)")
    loss = loss or Loss.least_squares()
    cache = {} if cache is None else cache
    folds = folds or folds_of(ds)
    spec = resolve_shapes(ds.signals, ds.target, spec, loss, cache)
    base = compare(ds, spec, loss, folds=folds, cache=cache)
    y = ds.target
    exc = excitation_of(ds)
    bases = base_per_fold(ds, spec, loss, folds, cache)
    base_pred = heldout_prediction(bases, ds.n)
    e0 = error_of(y - base_pred, y, loss)
    e0_folds = _fold_errors(y, base_pred, folds, loss)
    train0 = base.train.error
    todo = [e for e in resolve_effects(effects) if e.name not in spec.effect_names]
    probes = probe_gains(ds, bases, base.model, loss, e0)
    ranking = []
    for i, eff in enumerate(todo):
        if progress:
            progress(f"[{i + 1}/{len(todo)}] {eff.name}")
        missing = [s for s in eff.signals if s not in ("u", "u_tau", "u_v") and s not in ds.signals]
        if missing:
            ranking.append(_untestable(eff, f"needs signal(s) {missing}: not in the log"))
            continue
        if "u_tau" in eff.signals and "u" not in eff.signals and K_TAU not in spec.linear:
            ranking.append(_untestable(eff, "needs k_tau in the model: it acts on the torque part k_tau tau"))
            continue
        reason = units_plausible(exc) or (eff.needs(exc) if eff.needs is not None else None)
        pred, failures = _score_effect(ds, eff, bases, loss, cache)
        if np.isnan(pred).any():
            ranking.append(_untestable(eff, f"no shape could be fitted: {failures[0] if failures else '?'}"))
            continue
        e1, gain, fold_gains, consistent = _heldout_gain(y, pred, e0, e0_folds, folds, loss)
        try:
            full, e_train = _full_fit(ds, spec, eff, loss, cache)
            shape, coef = full.spec.terms[-1].shape, full.coefficients[eff.name]
        except IdentificationError as exc_:
            shape, coef, e_train = {}, float("nan"), train0
            failures.append(str(exc_))
        probe = probes.get(eff.family)
        explained = None if probe is None or probe <= 0 else min(gain / probe, 1.0) if gain > 0 else 0.0
        ranking.append(Candidate(
            effect=eff.name,
            heldout_gain=gain,
            heldout_error=e1,
            train_gain=1.0 - e_train / train0 if train0 > 0 else 0.0,
            fold_gains=fold_gains,
            consistent=consistent,
            shape=dict(shape),
            coefficient=coef,
            at_grid_edge=at_grid_edge(eff, shape, ds.signals),
            testable=reason is None,
            reason=reason,
            family=eff.family,
            explained=explained,
            partial=bool(explained is not None and explained < PARTIAL and probe - gain > 0.05),
        ))
    ranking, apart = lookalikes_apart(ranking, exc, min_gain, tuple(spec.effect_names))
    coefs = base.model.coefficients  # the regressors' noise floors scale with k_tau and k_v
    ranking = _checked(ds, spec, _ranked(within_resolution(ds, ranking, e0, loss, min_gain, coefs), min_gain), loss,
                       folds, min_gain, coefs)
    top = ranking[0] if ranking and ranking[0].testable else None
    if top is not None and top.heldout_gain >= min_gain and top.consistent and top.family in probes:
        try:
            with_top = spec.plus(Term(top.effect, top.shape))
            b2 = base_per_fold(ds, with_top, loss, folds, cache)
            p2 = heldout_prediction(b2, ds.n)
            fitted = fit_spec(ds.signals, y, with_top, loss, cache=cache)
            rem = probe_gains(ds, b2, fitted, loss, error_of(y - p2, y, loss), only=top.family)[top.family]
            partial = top.partial or (rem >= REMAINING and rem >= 0.25 * top.heldout_gain)
            ranking[0] = replace(top, remaining=rem, partial=partial)
        except IdentificationError:
            pass
    probes, floored = probes_within_resolution(ds, probes, e0, loss, coefs)  # then rechecked: the floored are 0
    probes, checks, constant_probes = recheck_probes(ds, spec, loss, folds, probes, ranking, min_gain)
    checks += floored + apart
    constant = [c.effect for c in ranking if c.reason and CONSTANT_ERROR in c.reason]
    if constant:
        checks += (f"{', '.join(constant)} {'loses its' if len(constant) == 1 else 'lose their'} gain {OFFSET_PROBE}: "
                   f"{OFFSET_ADVICE} (an encoder's zero, or a dead zone under a load of one sign; a motor model for "
                   "control takes no offset)",)
    else:
        checks += constant_error(ds, spec, loss, folds, e0, min_gain, cache)
    d = verdict_of(ds, spec, base, tuple(ranking), probes, exc, min_gain, checks, constant_probes=constant_probes)
    if d.verdict != "missing_effect" or not next_effect:
        return d
    then = _then_or_none(ds, spec, d.top, ranking, loss, folds, min_gain, cache)
    rival = tied_rival(ranking, d.top)
    if rival is not None and nameable(rival, min_gain):
        # the blocks do not order the two: the one whose next effect leaves the smaller error goes first
        then_r = _then_or_none(ds, spec, rival, ranking, loss, folds, min_gain, cache)
        if _two_steps(rival, then_r) < _two_steps(d.top, then):
            ranking = [c for c in ranking if c is not rival]
            ranking.insert(ranking.index(d.top), rival)
            then = then_r
            if then is None:
                return verdict_of(ds, spec, base, tuple(ranking), probes, exc, min_gain, checks, None)
    return d if then is None else verdict_of(ds, spec, base, tuple(ranking), probes, exc, min_gain, checks, then)


def _then_or_none(ds: Dataset, spec: ModelSpec, top: Candidate, ranking: list[Candidate], loss: Loss,
                  folds: list[Fold], min_gain: float, cache: dict) -> Candidate | None:
    try:
        return _then(ds, spec, top, ranking, loss, folds, min_gain, cache)
    except IdentificationError as exc_:
        log.info("no next effect after %s: %s", top.effect, exc_)
        return None


def _two_steps(first: Candidate, then: Candidate | None) -> float:
    """The held-out error with ``first`` and, if any, the next effect to add after it."""
    return first.heldout_error if then is None else then.heldout_error


def _order(c: Candidate) -> tuple:
    """Testable first, then by held-out gain (not-a-number last)."""
    return not c.testable, -c.heldout_gain if math.isfinite(c.heldout_gain) else math.inf


def _ranked(candidates: list[Candidate], min_gain: float) -> list[Candidate]:
    """``candidates`` by :func:`_order`, where an effect that nests another (``Effect.nests``, e.g. the Stribeck
    curve nests Coulomb friction) and would come before it moves just behind it unless its extra freedom removes
    ``min_gain`` of the held-out error the nested effect leaves: the part it adds has to be nameable on its own,
    or the simpler effect is named."""
    out = sorted(candidates, key=_order)
    for c in [c for c in out if c.testable]:
        for name in resolve_effects([c.effect])[0].nests:
            j = next((k for k, b in enumerate(out) if b.effect == name and b.testable), None)
            i = out.index(c)
            if j is None or j < i or c.heldout_gain - out[j].heldout_gain >= min_gain * (1.0 - out[j].heldout_gain):
                continue
            out.insert(j, out.pop(i))
    return out


def _checked(ds: Dataset, spec: ModelSpec, ranking: list[Candidate], loss: Loss, folds: list[Fold],
             min_gain: float, coefficients: Mapping[str, float]) -> list[Candidate]:
    """``ranking`` (sorted) where a lag-like effect (family ``dynamics``) that would come first and be named keeps
    its place only if it still removes ``min_gain``, and more than the log's noise floor
    (:func:`~.resolution.error_floor` with the model's ``coefficients``), with every less biased derivative
    (:func:`~.checks.derivative_checks`), with a less biased torque smoothing (:func:`~.checks.smoothing_check`)
    and, on a servo-error log whose model has no constant offset, with one (a
    constant error, e.g. an encoder's zero or a dead zone under a load of one sign, biases ``k_tau``, and lag-like
    terms fit the bias). A function of the velocity (family ``velocity``) is checked with the less biased
    derivatives only, a function of the position (family ``position``) with the offset only (``CHECKED``).
    Otherwise it is untestable, saying why, and the next one is considered.
    Friction-like effects are not checked against the offset: a dead zone under a load of mostly one sign, or an
    asymmetric Coulomb friction on a joint that rarely rests, is partly a constant and still physical."""
    preprocessed = None  # the log with less biased preprocessing (checks.preprocessing_checks), built on first need
    offset = offset_spec(ds, spec)
    while True:
        i = next((k for k, c in enumerate(ranking) if nameable(c, min_gain)), None)
        causes = CHECKED.get(ranking[i].family, ()) if i is not None else ()
        if not causes:
            break
        top = ranking[i]
        if preprocessed is None and {DIFFERENTIATION, SMOOTHING} & set(causes):
            preprocessed = preprocessing_checks(ds)
        alternatives = [(d, spec, f"with {how}", cause) for d, how, cause in preprocessed or () if cause in causes]
        if offset is not None and CONSTANT_ERROR in causes:
            alternatives.append((ds, offset, f"{OFFSET_PROBE} (--offset on)", CONSTANT_ERROR))
        if not alternatives:
            break
        eff = resolve_effects([top.effect])[0]
        failed = None
        for d, sp, how, cause in alternatives:
            g, removed = _gain_with(d, sp, eff, loss, folds)
            floor = error_floor(d, loss, coefficients)
            if g < min_gain or (0 < floor and removed <= floor):
                failed = (g, removed, floor, how, cause) if failed is None or g < failed[0] else failed
        if failed is None:
            break
        g, removed, floor, how, cause = failed
        within = f", {1e6 * removed:.3g} urad RMS within the noise floor {1e6 * floor:.3g}" if g >= min_gain else ""
        ranking[i] = replace(top, testable=False, reason=f"cannot tell: may be {cause} (held-out gain {100 * g:.0f} % "
                                                         f"{how}{within})")
        ranking = _ranked(ranking, min_gain)
    return ranking


def _then(ds: Dataset, spec: ModelSpec, top: Candidate, ranking: list[Candidate], loss: Loss, folds: list[Fold],
          min_gain: float, cache: dict) -> Candidate | None:
    """The effect to add after ``top``: each other testable effect scored over the model with ``top`` (same blocks,
    nested shape choice, resolution floor and derivative checks); the best if the verdict could name it, else
    None. Its gains are over the model with ``top``."""
    y = ds.target
    with_top = spec.plus(Term(top.effect, top.shape))
    bases = base_per_fold(ds, with_top, loss, folds, cache)
    pred0 = heldout_prediction(bases, ds.n)
    e0 = error_of(y - pred0, y, loss)
    e0_folds = _fold_errors(y, pred0, folds, loss)
    if not e0 > 0:
        return None
    out = []
    for c in ranking:
        if not c.testable or c.effect == top.effect:
            continue
        pred, _ = _score_effect(ds, resolve_effects([c.effect])[0], bases, loss, cache)
        if np.isnan(pred).any():
            continue
        e1, gain, fold_gains, consistent = _heldout_gain(y, pred, e0, e0_folds, folds, loss)
        out.append(replace(c, heldout_gain=gain, heldout_error=e1, fold_gains=fold_gains, consistent=consistent,
                           explained=None, partial=False, remaining=None))
    fitted = fit_spec(ds.signals, y, with_top, loss, cache=cache)
    out = _ranked(within_resolution(ds, out, e0, loss, min_gain, fitted.coefficients), min_gain)
    out = _checked(ds, with_top, out, loss, folds, min_gain, fitted.coefficients)
    best = next((c for c in out if nameable(c, min_gain)), None)
    if best is None:
        return None
    eff = resolve_effects([best.effect])[0]
    full, e_train = _full_fit(ds, with_top, eff, loss, cache)  # shape and coefficient over the model with top
    train0 = error_of(y - fitted.predict(ds.signals), y, loss)
    shape = full.spec.terms[-1].shape
    return replace(best, shape=dict(shape), coefficient=full.coefficients[eff.name],
                   train_gain=1.0 - e_train / train0 if train0 > 0 else 0.0,
                   at_grid_edge=at_grid_edge(eff, shape, ds.signals))


def _gain_with(ds: Dataset, spec: ModelSpec, eff: Effect, loss: Loss, folds: list[Fold]) -> tuple[float, float]:
    """Held-out gain of ``eff`` over ``spec`` on ``ds`` (the same blocks and nested shape choice), and the error it
    removes (:func:`~.resolution.removed_error`)."""
    cache: dict = {}
    bases = base_per_fold(ds, spec, loss, folds, cache)
    base_pred = heldout_prediction(bases, ds.n)
    e0 = error_of(ds.target - base_pred, ds.target, loss)
    pred, _ = _score_effect(ds, eff, bases, loss, cache)
    if np.isnan(pred).any() or not e0 > 0:
        return 0.0, 0.0
    e1 = error_of(ds.target - pred, ds.target, loss)
    return 1.0 - e1 / e0, removed_error(e0, e1)


def _untestable(eff: Effect, reason: str) -> Candidate:
    nan = float("nan")
    return Candidate(eff.name, nan, nan, nan, (), False, {}, nan, False, False, reason, eff.family)
