"""The diagnosis's result (:class:`Diagnosis`, its :class:`Candidate` effects and :class:`Confusion`) and its
verdict (see :mod:`.diagnose`): ``missing_effect``, ``unexplained`` or ``no_missing_effect``, with the message
that says why, the experiments that separate look-alike effects, and the residual's tail.

The probes that the workbench's own differentiation can feed (``CHECKED_PROBES``) call a log ``unexplained`` only
if they survive less biased derivatives (:func:`recheck_probes`). A log whose units are doubted or whose joint never
moves (:class:`~servotau.actuator.Excitation`'s ``unit_doubts`` and ``faults``) gets a message that starts
"cannot tell which effect" (every effect is then untestable). So does a log that a probe would call ``unexplained``
until a constant offset, which the model lacks, is added (:func:`recheck_probes`): a free function of a velocity
that never reverses fits a constant, and the diagnosis is to be rerun with the offset.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from servotau.actuator import EXPERIMENTS, Effect, Excitation, get_effect
from servotau.errors import IdentificationError

from ..data.folds import Fold
from .checks import CONSTANT_ERROR, OFFSET_ADVICE, offset_spec, preprocessing_checks
from .data import Dataset
from .evaluate import Comparison, error_of
from .model import FittedModel, ModelSpec, design, fit_spec
from .probes import MEMORY_HORIZON_S, base_per_fold, heldout_prediction, memory_candidates, probe_gains
from .resolution import probes_within_resolution

PROBE_FACTOR = 2.0
"""A probe (tens of free parameters) names ``unexplained`` structure from ``PROBE_FACTOR * min_gain`` on."""

TAIL_FRACTION = 0.02
TAIL_SHARE = 0.5
"""``unexplained`` also when the ``TAIL_FRACTION`` largest held-out residuals carry more than ``TAIL_SHARE`` of
the squared error (about 0.14 for Gaussian residuals) and most of them sit at the largest servo effort: the
model fails at its limit (saturation). Residuals of real servos are heavy-tailed anyway (dead-band crossings
carry two thirds of the squared error of the simulated default servo), hence the second condition."""

VERDICTS = ("missing_effect", "no_missing_effect", "unexplained", "cannot_tell")
"""``cannot_tell``: the log itself cannot decide (units doubted, a joint that never moves: every effect is
untestable), or the model lacks the constant offset that would let it decide; the message says why."""

TIE = 0.01
"""Two effects whose held-out errors differ by less than this fraction tie: the blocks do not order them
(:func:`tied_rival`)."""

LOOKALIKE_SHARE = 0.5
"""An effect that ``needs`` calls untestable only for want of the excitation that tells it from its look-alikes is
tested where each of them removes at most this share of the held-out error it removes (:func:`lookalikes_apart`)."""

OFFSET_PROBE = "with a constant offset in the model, which it lacks"
"""How a check over the model with an offset is named in its sentence: a probe's (:func:`recheck_probes`) or an
effect's (:func:`~.diagnose._checked`)."""
CANNOT_TELL = "cannot tell which effect: "
"""How a ``cannot_tell`` message starts: its reasons follow, then the ranking as the log reads."""
NO_TORQUE = ("the log has no torque (no column, or one that never changes): the model has no k_tau tau, so an effect "
             "named may stand for the servo's load (gravity, inertia); a torque column tells them apart")
"""The caveat in the checks of a servo-error log without torque."""

CHECKED_PROBES = ("dynamics", "memory")
"""Probes that the preprocessing's own error can feed (lagged inputs; the residual's past, smooth over the
velocity's or the torque's window): before they call a log ``unexplained`` they are re-run with each less biased
derivative and torque smoothing (:func:`recheck_probes`), and the smallest gain counts."""


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
    """Result of :func:`~servotau.identification.workbench.diagnose.diagnose`.

    Attributes:
        verdict: One of :data:`VERDICTS`.
        base: The current model against the measurement (training and held-out).
        ranking: Every effect, testable ones first, by held-out gain.
        probes: Held-out gain of each non-parametric probe family.
        excitation: What the data exercised.
        min_gain: Threshold used.
        confusion: The top two effects if they are a documented confusable pair (or nearly tie).
        message: One-paragraph human summary.
        checks: What the checks against the workbench's own preprocessing changed (e.g. a probe re-run with a
            less biased derivative), one sentence each.
        then: With ``missing_effect``, the effect to add next: the best one over the model with the named effect,
            if the verdict could name it there (its gains are over that model), else None.
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
    checks: tuple[str, ...] = ()
    then: Candidate | None = None

    @property
    def top(self) -> Candidate | None:
        """The named effect (the best testable one that clears ``min_gain`` in enough blocks), else the best
        testable one if it is first in the ranking."""
        named = next((c for c in self.ranking if nameable(c, self.min_gain)), None)
        if named is not None:
            return named
        return self.ranking[0] if self.ranking and self.ranking[0].testable else None

    @property
    def shortlist(self) -> tuple[Candidate, ...]:
        """The first two effects to add, in order (add one, watch the error fall, re-rank): the first testable
        effect of the ranking, and second the next to add over the model with it (:attr:`then`, greedy forward
        selection) when the first is the named effect. Two effects hidden together rank as the first one and its
        look-alikes over the base model; the second shows once the first is in. Otherwise the ranking's first two
        testable effects."""
        tested = [c for c in self.ranking if c.testable]
        if not tested or self.then is None or self.top is not tested[0]:
            return tuple(tested[:2])
        return tested[0], self.then

    @property
    def runner_up(self) -> Candidate | None:
        top = self.top
        return next((c for c in self.ranking if c.testable and c is not top), None)

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
            "checks": list(self.checks),
            "then": None if self.then is None else self.then.to_dict(),
            "shortlist": [c.effect for c in self.shortlist],
            "train": self.base.train.to_dict(),
            "heldout": None if self.base.heldout is None else self.base.heldout.to_dict(),
            "excitation": self.excitation.to_dict(),
        }


def tied_rival(ranking, top: Candidate) -> Candidate | None:
    """The first testable effect ranked after ``top`` that does not nest it (the nesting rule already put such an
    effect behind, its extra part not nameable), if its held-out error is within ``TIE`` of ``top``'s: as good a
    first as ``top``."""
    after = [c for c in ranking[ranking.index(top) + 1:] if c.testable]
    rival = next((c for c in after if top.effect not in get_effect(c.effect).nests), None)
    if rival is None or not rival.heldout_error <= (1.0 + TIE) * top.heldout_error:
        return None
    return rival


def lookalikes_apart(ranking: list[Candidate], exc: Excitation, min_gain: float, in_model: tuple[str, ...] = ()
                     ) -> tuple[list[Candidate], tuple[str, ...]]:
    """``ranking`` where an effect untestable only because the log lacks the excitation that tells it from its
    look-alikes (its reason is ``Effect.lookalike_needs``'s) is testable when that reason does not hold on the log:
    it would be named first (it removes ``min_gain`` of the held-out error, more than any testable effect), and each
    look-alike was scored and removes at most ``LOOKALIKE_SHARE`` of what it removes, or is in the model
    (``in_model``). With a sentence for each such effect (the reason stays true of the log, and the experiment
    still helps). It reads the ranking before the derivative, offset and resolution checks: an effect those later
    make untestable still counts as removing what it removed (the cautious side)."""
    by_name = {c.effect: c for c in ranking}
    best = max((c.heldout_gain for c in ranking if c.testable and math.isfinite(c.heldout_gain)), default=-math.inf)
    out, notes = [], []
    for c in ranking:
        eff = get_effect(c.effect)
        if (eff.lookalike_needs is not None and not c.testable and c.heldout_gain >= max(min_gain, best)
                and c.consistent and c.reason == eff.lookalike_needs(exc)
                and all(n in by_name or n in in_model for n in eff.needs_lookalikes)):
            rivals = {n: by_name[n].heldout_gain for n in eff.needs_lookalikes if n in by_name}
            rivals = {n: g if math.isfinite(g) else 0.0 for n, g in rivals.items()}
            if all(g <= LOOKALIKE_SHARE * c.heldout_gain for g in rivals.values()):
                removes = "; ".join([f"{n} {100 * g:.0f} %" for n, g in rivals.items()]
                                    + [f"{n} in the model" for n in eff.needs_lookalikes if n in in_model])
                notes.append(f"{c.effect} is tested although {c.reason.split(';')[0].split(':')[0]}: its look-alikes "
                             f"remove little of the held-out error on this log ({removes}; {c.effect} "
                             f"{100 * c.heldout_gain:.0f} %)")
                c = replace(c, testable=True, reason=None)
        out.append(c)
    return out, tuple(notes)


def at_grid_edge(effect: Effect, shape: Mapping[str, float], signals) -> bool:
    """The chosen ``shape`` is the first or last value of a one-parameter grid (of 3 shapes or more)."""
    if callable(effect.grid):
        return False
    grid = effect.grid_for(signals)
    keys = [k for k in grid[0] if len({g[k] for g in grid}) > 1]
    if len(keys) != 1 or len(grid) < 3:
        return False
    values = sorted({g[keys[0]] for g in grid})
    return shape.get(keys[0]) in (values[0], values[-1])


def nameable(c: Candidate, min_gain: float) -> bool:
    """The verdict may name ``c``: testable, removes ``min_gain`` of the held-out error, helps in enough blocks."""
    return c.testable and c.heldout_gain >= min_gain and c.consistent


def _r(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(f"{x:.6g}")


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


def recheck_probes(ds: Dataset, spec: ModelSpec, loss, folds: list[Fold], probes: Mapping[str, float],
                   ranking, min_gain: float) -> tuple[dict[str, float], tuple[str, ...], tuple[str, ...]]:
    """``probes`` with the gains of ``CHECKED_PROBES`` that would call the log ``unexplained`` (no effect named)
    replaced by the smallest of theirs and the same probe's with each less biased derivative
    and with a less biased torque smoothing (:func:`~.checks.preprocessing_checks`), and the gain of any probe that
    would call it so replaced by its gain over the model with a constant offset when the model of a servo error
    lacks one (:func:`~.checks.offset_spec`: a free function of a velocity that never reverses fits a constant);
    a sentence per probe that fell below the threshold; and the probes that fell below it over the model with the
    offset (found only the constant). Unchanged when an effect is named or no such probe reaches
    ``PROBE_FACTOR * min_gain``."""
    out = dict(probes)
    if any(nameable(c, min_gain) for c in ranking):
        return out, (), ()
    todo = [k for k in CHECKED_PROBES if out.get(k, 0.0) >= PROBE_FACTOR * min_gain]
    checks = [(fds, spec, f"with {how}", cause) for fds, how, cause in (preprocessing_checks(ds) if todo else [])]
    offset = offset_spec(ds, spec)
    if offset is not None:  # last: only the probes that survive the other checks
        checks.append((ds, offset, OFFSET_PROBE, CONSTANT_ERROR))
    notes, constant = [], []
    for fds, fspec, how, cause in checks:
        keys = [k for k, g in out.items() if g >= PROBE_FACTOR * min_gain] if cause == CONSTANT_ERROR else todo
        if not keys:
            continue
        cache: dict = {}
        try:
            bases = base_per_fold(fds, fspec, loss, folds, cache)
            pred = heldout_prediction(bases, fds.n)
            e0 = error_of(fds.target - pred, fds.target, loss)
            model = fit_spec(fds.signals, fds.target, fspec, loss, cache=cache)
            raw = probe_gains(fds, bases, model, loss, e0)
            again, _ = probes_within_resolution(fds, raw, e0, loss, model.coefficients)
        except IdentificationError as exc:
            notes.append(f"the check of the {', '.join(keys)} probe {how} failed: {exc}")
            continue
        for k in keys:
            g = again.get(k, 0.0)
            if g < out[k]:
                if g < PROBE_FACTOR * min_gain <= out[k]:
                    if cause == CONSTANT_ERROR:
                        constant.append(k)
                    if g < raw.get(k, 0.0):  # floored: what it removes there is within that log's noise floor
                        notes.append(f"cannot tell: the {k} probe's {100 * out[k]:.0f} % is {100 * raw[k]:.0f} % "
                                     f"{how}, within the log's noise floor there: it may be {cause}")
                    else:
                        notes.append(f"cannot tell: the {k} probe's {100 * out[k]:.0f} % falls to {100 * g:.0f} % "
                                     f"{how}: it may be {cause}")
                out[k] = g
    return out, tuple(notes), tuple(constant)


def _cannot_tell(reason: str, message: str) -> str:
    """The message of a ``cannot_tell`` verdict: the reason, then what the ranking says as the log reads (its
    verdict would be misread as the answer), or the earlier reasons."""
    if message.startswith(CANNOT_TELL):
        return f"{CANNOT_TELL}{reason}; {message[len(CANNOT_TELL):]}"
    return f"{CANNOT_TELL}{reason}; the ranking as the log reads: {message}"


def verdict_of(ds, spec, base, ranking, probes, exc, min_gain, checks: tuple[str, ...] = (),
               then: Candidate | None = None, constant_probes: tuple[str, ...] = ()) -> Diagnosis:
    if ds.actuator and not ds.has_torque:
        checks = (*checks, NO_TORQUE)
    named = [c for c in ranking if nameable(c, min_gain)]
    experiments = {}
    confusion = None
    if named:
        top = named[0]
        verdict = "missing_effect"
        # the best other tested effect (the named one is not first when a better one failed in too many blocks)
        second = next((c for c in ranking if c.testable and c.effect != top.effect), None)
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
        shape = (eff.shape_text(top.coefficient, top.shape) if eff.shape_text is not None
                 else ", ".join(f"{k} = {v:.3g}" for k, v in top.shape.items()))
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
        if then is not None:
            message += (f"; with {top.effect} in the model, {then.effect} removes a further "
                        f"{100 * then.heldout_gain:.0f} % (the next to add)")
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
                                   f"predicts {100 * memory:.0f} % of it: a state no term models; candidates: "
                                   + "; ".join(memory_candidates(ranking, min_gain)))
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
    if checks:
        message += "; " + "; ".join(checks)
    if verdict == "no_missing_effect" and constant_probes:  # (recheck_probes) they found only a constant
        found = (f"the {constant_probes[0]} probe finds" if len(constant_probes) == 1 else
                 f"the {', '.join(constant_probes[:-1])} and {constant_probes[-1]} probes find")
        verdict, message = "cannot_tell", _cannot_tell(f"a constant error, which the model lacks, stands in for what "
                                                       f"{found} ({OFFSET_ADVICE})", message)
    if exc.unit_doubts:
        verdict, message = "cannot_tell", _cannot_tell(f"units doubted ({'; '.join(exc.unit_doubts)})", message)
    faults = list(exc.faults)
    y = ds.target
    if not faults and y.size and np.ptp(y) == 0.0:  # e.g. q_des logged as a copy of q
        faults.append(f"the target never changes (= {y[0]:.6g}): there is no error to model")
    if faults:
        verdict, message = "cannot_tell", _cannot_tell("; ".join(faults), message)
    return Diagnosis(verdict, base, ranking, probes, exc, min_gain, confusion, message, experiments, _tail(ds, base)[0],
                     checks, then if verdict == "missing_effect" else None)




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
