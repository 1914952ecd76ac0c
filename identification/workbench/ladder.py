"""Add effects and watch the error fall: the ladder of models, each with training and held-out error.

Greedy mode (no effect named): diagnose the current model, add the top effect if the verdict is
``missing_effect``, refit everything with the same loss, diagnose again, until nothing is missing or
``max_steps`` effects were added. A step whose refit does not lower the held-out error (the diagnosis
ranks an effect with the other shapes held; refitting them all can overfit) is not kept: it is listed
in :attr:`Ladder.rejected` and the search stops. Named mode: add the given effects in order, then diagnose the result.
On every rung, the shapes the caller did not fix are chosen again jointly (coordinate descent over the
grids, ``SWEEPS`` passes): an effect that was missing bends the shapes of the others.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from servotau.actuator import FitMetrics, Loss, MotorModel, MotorParameters, get_effect
from servotau.actuator.model import SERVO_ERROR, SERVO_UNIT
from servotau.errors import IdentificationError

from ..data.folds import Fold, folds_of
from .data import Dataset
from .diagnose import MIN_GAIN, Diagnosis, diagnose
from .evaluate import Comparison, compare
from .model import FittedModel, ModelSpec, Term, resolve_shapes
from .verdict import _r

SWEEPS = 3


@dataclass(frozen=True, eq=False)
class Rung:
    """One model of the ladder: what was added, the comparison (training and held-out)."""

    label: str
    added: str | None
    comparison: Comparison

    def to_dict(self) -> dict:
        c = self.comparison
        return {
            "model": self.label,
            "added": self.added,
            "shape": None if self.added is None else dict(c.model.spec.terms[-1].shape),
            "train_rms": _r(c.train.rms),
            "heldout_rms": _r(c.heldout.rms) if c.heldout else None,
            "train_error": _r(c.train.error),
            "heldout_error": _r(c.heldout.error) if c.heldout else None,
            "heldout_fit_percent": _r(c.heldout.fit_percent) if c.heldout else None,
            "overestimation_rate": _r(c.train.overestimation_rate),
            "coefficients": {k: _r(v) for k, v in c.model.coefficients.items()},
        }


@dataclass(frozen=True, eq=False)
class Ladder:
    """The models in the order they were built, and the diagnoses that chose each step.

    Attributes:
        rungs: Base model first.
        diagnoses: ``diagnoses[i]`` ranked the effects missing from ``rungs[i]`` (the last one gives the
            final verdict; named mode has only the last).
        loss: Loss of every fit.
        rejected: Greedy steps tried and not kept (their refit raised the held-out error).
    """

    rungs: tuple[Rung, ...]
    diagnoses: tuple[Diagnosis, ...]
    loss: Loss
    rejected: tuple[Rung, ...] = ()  # greedy steps whose refit did not lower the held-out error

    @property
    def final(self) -> FittedModel:
        return self.rungs[-1].comparison.model

    @property
    def verdict(self) -> str | None:
        """Verdict on the final model (None if it was not diagnosed)."""
        return self.diagnoses[-1].verdict if self.diagnoses else None

    def fall(self) -> float:
        """Fraction of the base model's held-out error removed by the final model."""
        e0 = self.rungs[0].comparison.heldout.error
        return 1.0 - self.rungs[-1].comparison.heldout.error / e0 if e0 > 0 else 0.0

    def to_dict(self) -> dict:
        return {
            "verdict": self.verdict,
            "ladder": [r.to_dict() for r in self.rungs],
            "rejected": [r.to_dict() for r in self.rejected],
            "heldout_fall": _r(self.fall()),
            "loss": str(self.loss),
        }


def add_effects(
    ds: Dataset,
    spec: ModelSpec,
    loss: Loss | None = None,
    *,
    effects: Iterable[str] | None = None,
    candidates: Iterable[str] | None = None,
    max_steps: int = 4,
    min_gain: float = MIN_GAIN,
    folds: list[Fold] | None = None,
    progress: Callable[[str], None] | None = None,
    diagnose_final: bool = True,
) -> Ladder:
    """Build the ladder from ``spec`` (see the module doc).

    Args:
        ds: The data.
        spec: The base model.
        loss: Loss of every fit (default least squares).
        effects: Effects to add in this order; None: greedy, by diagnosis.
        candidates: Effects the greedy search may add (default all registered).
        max_steps: Most effects added by the greedy search.
        min_gain: Threshold of :func:`~servotau.identification.workbench.diagnose.diagnose`.
        folds: Held-out blocks.
        progress: Called with short messages.
        diagnose_final: In named mode, rank what is still missing from the final model (the verdict).
    """
    loss = loss or Loss.least_squares()
    folds = folds or folds_of(ds)
    cache: dict = {}
    say = progress or (lambda _msg: None)
    free = [t.shape is None for t in spec.terms]  # shapes not given by the caller are chosen again on every rung
    spec = resolve_shapes(ds.signals, ds.target, spec, loss, cache, sweeps=SWEEPS)
    rungs = [Rung(spec.label(), None, compare(ds, spec, loss, folds=folds, cache=cache))]
    diagnoses: list[Diagnosis] = []

    def climb(name: str) -> None:
        nonlocal free, spec
        free = [*free, True]
        spec = resolve_shapes(ds.signals, ds.target, spec.plus(Term(name)), loss, cache, sweeps=SWEEPS, free=free)
        rungs.append(Rung(spec.label(), name, compare(ds, spec, loss, folds=folds, cache=cache)))

    if effects is not None:
        for name in effects:
            get_effect(name)
            if name in spec.effect_names:
                raise IdentificationError(f"effect '{name}' is already in the model {spec.label()}")
            say(f"adding {name}")
            climb(name)
        if diagnose_final:
            say("diagnosing the final model")
            diagnoses.append(diagnose(ds, spec, loss, effects=_remaining(candidates, spec), folds=folds,
                                      min_gain=min_gain, cache=cache, progress=progress))
        return Ladder(tuple(rungs), tuple(diagnoses), loss)
    rejected: list[Rung] = []
    for step in range(max_steps + 1):
        say(f"step {step}: diagnosing {spec.label()}")
        d = diagnose(ds, spec, loss, effects=_remaining(candidates, spec), folds=folds, min_gain=min_gain,
                     cache=cache, progress=progress, next_effect=False)
        diagnoses.append(d)
        if d.verdict != "missing_effect" or step == max_steps:
            break
        top = d.top
        say(f"adding {top.effect} ({100 * top.heldout_gain:.0f} % of the held-out error); refitting the shapes")
        kept_spec, kept_free = spec, free
        climb(top.effect)
        before, after = rungs[-2].comparison.heldout, rungs[-1].comparison.heldout
        if before is not None and after is not None and after.error >= before.error:
            rejected.append(rungs.pop())
            spec, free = kept_spec, kept_free
            say(f"{top.effect} not kept: refitted, the held-out RMS went {before.rms:.3g} -> {after.rms:.3g}; stopping")
            break
    return Ladder(tuple(rungs), tuple(diagnoses), loss, tuple(rejected))


def _remaining(candidates: Iterable[str] | None, spec: ModelSpec) -> list[str] | None:
    if candidates is None:
        return None
    return [c for c in candidates if c not in spec.effect_names]


def save_model(
    ladder_or_model: Ladder | FittedModel,
    path: str | Path,
    joint: str,
    *,
    provenance: str,
    metrics: FitMetrics | None = None,
    dead_band_log: str | Path | None = None,
    target: str = SERVO_ERROR,
    unit: str = SERVO_UNIT,
) -> Path:
    """Write the model of ``target`` in ``unit`` (the dataset's, e.g. from
    :func:`~servotau.identification.workbench.units.unit_of`: ``quantity`` and ``si``) into the motor-parameter
    file ``path`` under ``joint`` (other joints of an existing file, and its comment lines, are kept). Terms not in
    the model (``k_tau`` of a table without torque) are left out of the file; an ``offset`` is saved.

    ``dead_band_log``: a servotau log whose holds give the joint's ``deadzone`` term instead of the fitted one
    (:func:`~servotau.identification.deadband.with_log_dead_bands`, with the model's ``k_tau``): the motor file
    of the controller in one step.

    Raises:
        IdentificationError: With ``dead_band_log``, the model is not a servo-error model with ``k_tau``."""
    if isinstance(ladder_or_model, Ladder):
        model = ladder_or_model.final
        train = ladder_or_model.rungs[-1].comparison.train
        metrics = metrics or FitMetrics(train.rms, train.overestimation_rate, train.n)
    else:
        model = ladder_or_model
    motor = model.to_motor_model(provenance, metrics, target=target, unit=unit)
    if dead_band_log is not None:
        from ..deadband import with_log_dead_bands

        motor.check_servo(f"dead band from {dead_band_log}: model {model.spec.label()}")

        motor = with_log_dead_bands(MotorParameters({joint: motor}), dead_band_log)[0][joint]
    p = Path(path)
    models: Mapping[str, MotorModel] = dict(MotorParameters.load_toml(p)) if p.exists() else {}
    notes = []
    if p.exists():  # the file's provenance stays with its other joints; the notes say which one is new
        notes = [*MotorParameters.notes_of(p), f"{joint}: replaced by a model fitted on {provenance} (what the notes "
                 f"above say of {joint} predates it)"]
    return MotorParameters({**models, joint: motor}).save_toml(p, notes)
