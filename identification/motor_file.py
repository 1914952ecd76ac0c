"""The controller's motor file from one identification log, without a manual step (``servotau identify run``).

Per joint:

1. **The paper's model** (k_tau, k_v; eq. 8, asymmetric penalty, w = 100) and the effects the model workbench
   adds to it (:func:`~servotau.identification.workbench.ladder.add_effects`: greedy, each step kept only when its
   refit lowers the blocked cross-validated (held-out) error; candidates :data:`CANDIDATES`).
2. **The dead band measured on the holds** (:mod:`~servotau.identification.deadband`: half the jump of the rest
   residual at the torque reversal) replaces the model's ``deadzone`` term (or adds one) when, measured on the
   training blocks, it lowers the held-out error at rest (where it acts; :func:`_dead_band_choice`).

Every choice is recorded in a :class:`JointChoice` (what was tried, the errors, why it was kept or not).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from servotau.actuator import FitMetrics, Loss, MotorModel, MotorParameters
from servotau.errors import IdentificationError

CANDIDATES = ("coulomb", "deadzone", "stribeck")  # effects the workbench may add (the servo effects of a position
# servo that a feedforward can use; the whole library costs ~5 s per diagnosis of 1e5 samples, per step and joint)
MAX_STEPS = 3
W = 100.0  # the paper's over-estimation weight
DECIMATE = 5  # the workbench reads every 5th sample of the 1 kHz log (2e4 samples of the default plan)
HOLDOUT_BLOCK = 1.0  # [s] blocks of the dead band's held-out split (as the pipeline's)
HOLDOUT_EVERY = 3  # one block in three held out


@dataclass(frozen=True)
class JointChoice:
    """What ``identify run`` chose for one joint, and why (errors in rad; the held-out error is the loss's criterion,
    sqrt of the asymmetric penalty, which the workbench lowers at every step it keeps)."""

    joint: str
    paper_heldout_error: float  # [rad] the paper's model, blocked cross-validation, the loss's criterion
    final_heldout_error: float  # [rad] the workbench's model, same
    paper_heldout_rms: float  # [rad] the paper's model, held-out RMS
    final_heldout_rms: float  # [rad] the workbench's model, held-out RMS
    effects: tuple[str, ...]  # kept by the workbench, in order
    rejected: tuple[str, ...]  # refitted and dropped (held-out error rose)
    dead_band: float | None  # [rad] measured on the holds (None: not measurable)
    dead_band_kept: bool
    rms_without_dead_band: float  # [rad] held-out samples at rest
    rms_with_dead_band: float  # [rad] held-out samples at rest (nan if not measurable)
    notes: tuple[str, ...] = ()

    def reason(self) -> str:
        eff = (f"effects {', '.join(self.effects)} (held-out error {1e3 * self.paper_heldout_error:.3f} -> "
               f"{1e3 * self.final_heldout_error:.3f} mrad, RMS {1e3 * self.paper_heldout_rms:.3f} -> "
               f"{1e3 * self.final_heldout_rms:.3f})" if self.effects
               else f"no effect lowers the held-out error ({1e3 * self.paper_heldout_error:.3f} mrad)")
        if self.rejected:
            eff += f"; tried and dropped: {', '.join(self.rejected)}"
        if self.dead_band is None:
            db = "dead band: not measurable on the holds"
        else:
            verdict = "kept" if self.dead_band_kept else "not kept"
            db = (f"dead band d = {1e3 * self.dead_band:.3f} mrad {verdict} (held-out RMS at rest "
                  f"{1e3 * self.rms_without_dead_band:.3f} -> {1e3 * self.rms_with_dead_band:.3f} mrad)")
        return f"{eff}; {db}"

    def to_dict(self) -> dict:
        return {"paper_heldout_error": self.paper_heldout_error, "final_heldout_error": self.final_heldout_error,
                "paper_heldout_rms": self.paper_heldout_rms, "final_heldout_rms": self.final_heldout_rms,
                "effects": list(self.effects), "rejected": list(self.rejected), "dead_band": self.dead_band,
                "dead_band_kept": self.dead_band_kept, "rms_without_dead_band": self.rms_without_dead_band,
                "rms_with_dead_band": self.rms_with_dead_band, "notes": list(self.notes), "reason": self.reason()}


@dataclass(frozen=True)
class MotorFileReport:
    """The motor file of ``identify run`` and the choice of every joint."""

    log: str
    params: MotorParameters = field(repr=False)
    choices: dict[str, JointChoice]

    def table(self) -> str:
        lines = [f"motor model per joint, from {self.log} (errors: servo error q_des - q):"]
        for j, c in self.choices.items():
            m = self.params[j]
            lines.append(f"  {j}: k_tau {m.k_tau:.3e} rad/(N m), k_v {m.k_v:.3e} s; {c.reason()}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"log": self.log, "joints": {j: {"k_tau": self.params[j].k_tau, "k_v": self.params[j].k_v,
                                                "extra": sorted(self.params[j].extra), **c.to_dict()}
                                            for j, c in self.choices.items()}}


def _workbench_model(columns: dict, joint: str, loss: Loss, candidates: Sequence[str], max_steps: int,
                     say: Callable[[str], None]):
    """The workbench's ladder from the paper's model on ``joint`` of the log's ``columns`` (with the estimates),
    and its dataset."""
    from .data.folds import DEFAULT_FOLDS, folds_of
    from .workbench.data import load_dataset
    from .workbench.ladder import add_effects
    from .workbench.model import parse_spec

    ds = load_dataset(columns, joint=joint)
    spec = parse_spec("paper", ds.signals, offset=False)
    ladder = add_effects(ds, spec, loss, candidates=list(candidates), max_steps=max_steps,
                         folds=folds_of(ds, DEFAULT_FOLDS), progress=lambda m: say(f"{joint}: {m}"))
    return ds, ladder


def _dead_band_choice(ds, motor: MotorModel) -> tuple[float | None, bool, float, float, tuple[str, ...]]:
    """The dead band on the holds, and whether it lowers the held-out error at rest.

    The samples are split in 1 s blocks, one in three held out (the pipeline's split). ``d`` is measured on the
    rest samples of the other blocks (half the jump of the rest residual at the torque reversal); the motor model
    with the dead band replacing its ``deadzone`` term is kept when its RMS on the held-out samples at rest
    (``|dq| < DQ_REST``, ``|tau| > TAU_MIN``: where the dead band acts) is below the model's. The kept ``d`` is then
    measured on every rest sample. Returns ``(d, kept, rms without, rms with, notes)``, RMS [rad]."""
    from servotau.actuator.effects.deadzone import DQ_REST, TAU_MIN, rest_dead_band, with_dead_band

    from .workbench.model import FittedModel

    sig = ds.signals
    target = np.asarray(ds.target, dtype=float)
    t, dq, tau = (np.asarray(sig[k], dtype=float) for k in ("t", "dq", "tau"))
    held = (np.floor((t - t[0]) / HOLDOUT_BLOCK).astype(int) % HOLDOUT_EVERY) == 0
    rest = (np.abs(dq) < DQ_REST) & (np.abs(tau) > TAU_MIN)
    try:
        d_train = rest_dead_band(target[~held], tau[~held], dq[~held], motor.k_tau).d
        d_all = rest_dead_band(target, tau, dq, motor.k_tau).d
    except IdentificationError as exc:
        return None, False, float("nan"), float("nan"), (f"dead band: {exc}",)
    rows = rest & held
    if rows.sum() < 10:
        return float(d_all), False, float("nan"), float("nan"), (f"dead band: {int(rows.sum())} held-out samples at "
                                                                 "rest: expected at least 10",)

    def rms(m: MotorModel) -> float:
        pred = FittedModel.from_motor_model(m).predict(sig)
        return float(np.sqrt(np.mean((target[rows] - pred[rows]) ** 2)))

    without = rms(motor)
    with_ = rms(with_dead_band(motor, max(float(d_train), 0.0)))
    kept = d_all > 0 and with_ < without
    return float(d_all), bool(kept), without, with_, ()


def build_motor_file(log: str | Path, joints: Sequence[str] | None = None, *, candidates: Sequence[str] = CANDIDATES,
                     max_steps: int = MAX_STEPS, w: float = W, decimate: int = DECIMATE, plan: str | Path | None = None,
                     progress: Callable[[str], None] | None = None) -> MotorFileReport:
    """The controller's motor model of every joint of ``log`` (module doc); the workbench reads every
    ``decimate``-th sample (the candidates are static effects; its diagnosis costs in proportion to the samples), the
    dead band every sample. ``plan``: the collection plan whose ``[fit]`` settings align the log (default
    config/identification.toml).

    Raises:
        IdentificationError: A joint whose model is not usable by the controller (k_tau <= 0, k_v < 0), naming
            the joint and the field; or the log's errors (missing columns, no holds, ...).
    """
    from servotau.actuator.effects.deadzone import with_dead_band

    from .data import load_aligned, read_table
    from .plan import load_plan
    from .workbench.data import load_dataset

    say = progress or (lambda _m: None)
    loss = Loss.asymmetric(w)
    _, settings = load_plan(plan) if plan is not None else load_plan()
    aligned = load_aligned(log, list(joints) if joints else None, settings, progress=say)
    # The workbench reads the log with the off-line estimates of every joint, estimated once here (as
    # `servotau model` does per joint when the log has none).
    columns = read_table(log)
    for joint, s in aligned.samples.items():
        columns[f"est/tau/{joint}"], columns[f"est/dq/{joint}"] = s.tau, s.dq
    decimated = {k: v[::decimate] for k, v in columns.items()} if decimate > 1 else columns
    models, choices = {}, {}
    for joint in aligned.samples:
        ds, ladder = _workbench_model(decimated, joint, loss, candidates, max_steps, say)
        base, final = ladder.rungs[0].comparison, ladder.rungs[-1].comparison
        held = final.heldout
        added = "+".join(ladder.final.spec.effect_names) or "none"
        motor = ladder.final.to_motor_model(
            f"{log}; servotau identify run; paper model + workbench ({added}), {loss}; tau, dq: off-line estimates "
            "from the log's sensors",
            FitMetrics(held.rms, held.overestimation_rate, held.n) if held is not None else None)
        motor.check_servo(f"{log}: joint {joint}")
        full = ds if decimate == 1 else load_dataset(columns, joint=joint)
        d, kept, rms_without, rms_with, notes = _dead_band_choice(full, motor)
        if kept:
            motor = with_dead_band(motor, d, provenance=f"{motor.provenance}; deadzone: measured on the holds "
                                   "(identification/motor_file.py, as identification/deadband.py)")
        models[joint] = motor
        nan = float("nan")
        choices[joint] = JointChoice(
            joint, float(base.heldout.error) if base.heldout else nan, float(held.error) if held is not None else nan,
            float(base.heldout.rms) if base.heldout else nan, float(held.rms) if held is not None else nan,
            tuple(r.added for r in ladder.rungs[1:]), tuple(r.added for r in ladder.rejected), d, kept,
            rms_without, rms_with, tuple(notes))
        say(f"{joint}: {choices[joint].reason()}")
    return MotorFileReport(str(log), MotorParameters(models), choices)


def write_motor_file(report: MotorFileReport, path: str | Path) -> Path:
    """Write the motor file with a header giving each joint's choice and its reason."""
    notes = [f"Written by `servotau identify run` from {report.log}: the paper's model (asymmetric, w = {W:g}),",
             "the model workbench's effects that lower the held-out error, the dead band measured on the holds",
             "when it lowers the held-out error at rest (identification/motor_file.py). Per joint:"]
    return report.params.save_toml(path, notes + [f"  {j}: {c.reason()}" for j, c in report.choices.items()])

