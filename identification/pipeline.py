"""From a recorded log to identified motor parameters (paper section 3), off-line.

1. **Read, estimate, align and split** with the data layer (:func:`~servotau.identification.data.load_aligned`):
   the log's contiguous segments estimated by the non-causal estimator after the settle phase's calibration,
   ``dq_err[k] = q_des[k] - q[k]`` paired with ``dq[k]`` and ``tau[k + tau_shift]``, and one hold-out split
   (blocks of ``holdout_block`` seconds, every ``holdout_every``-th held out, every ``downsample``-th sample
   kept). The ground truth a simulated log may carry is never used for the fit; it only gives an evaluation
   reference (:attr:`JointResult.reference`).
2. **Fit** per joint: least squares with and without Coulomb (eq. 7), the asymmetric penalty (eq. 8,
   Newton), the two-stage fit (section 3.3.1); metrics on the fitted and on the held-out samples.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from servotau.actuator import FitMetrics, MotorModel, MotorParameters
from servotau.actuator.loss import Loss
from servotau.errors import IdentificationError

from .data import AlignedLog, JointSamples, load_aligned
from .fit import fit_linear_model
from .linear_fit import LinearFit
from .metrics import overestimation_rate, residual_rms
from .plan import FitSettings
from .regressors import K_C, K_TAU, K_V
from .two_stage import TwoStageFit, fit_two_stage


@dataclass(frozen=True)
class VariantResult:
    """One fit of one joint: coefficients, metrics on its training samples and on the held-out ones."""

    name: str
    coefficients: dict[str, float]
    loss: str
    train_rms: float  # [rad]
    train_overestimation: float
    n_train: int
    heldout_rms: float  # [rad]
    heldout_overestimation: float
    n_heldout: int

    def to_dict(self) -> dict:
        return {"coefficients": self.coefficients, "loss": self.loss,
                "train": {"rms": self.train_rms, "overestimation_rate": self.train_overestimation,
                          "n_samples": self.n_train},
                "heldout": {"rms": self.heldout_rms, "overestimation_rate": self.heldout_overestimation,
                            "n_samples": self.n_heldout}}


@dataclass(frozen=True)
class JointResult:
    """All fits of one joint; ``written`` names the one that goes to the motor file."""

    joint: str
    variants: dict[str, VariantResult]
    written: str
    fit: LinearFit | TwoStageFit = field(repr=False)  # the written fit
    reference: dict[str, dict[str, float]] | None = None  # evaluation only: fits on the ground truth
    skipped: dict[str, str] = field(default_factory=dict)  # comparison fits that failed, with the reason

    def to_dict(self) -> dict:
        out = {"written": self.written, **{k: v.to_dict() for k, v in self.variants.items()}}
        if self.skipped:
            out["skipped"] = dict(self.skipped)
        if self.reference is not None:
            out["reference_ground_truth"] = self.reference
        return out


@dataclass(frozen=True)
class FitReport:
    """The result of ``servotau identify fit``."""

    log: str
    backend: str
    date: str
    settings: FitSettings
    joints: dict[str, JointResult]
    notes: tuple[str, ...] = ()
    motor_file: str | None = None

    def provenance(self, joint: str) -> str:
        r = self.joints[joint]
        v = r.variants[r.written]
        return (f"log={self.log}; date={self.date}; backend={self.backend}; fit={r.written} ({v.loss}), "
                f"{v.n_train} samples (downsample {self.settings.downsample}); metrics on {v.n_heldout} held-out "
                f"samples (1 block of {self.settings.holdout_block:g} s in {self.settings.holdout_every})")

    def motor_parameters(self) -> MotorParameters:
        """The written fit of every joint, with held-out metrics."""
        models = {}
        for joint, r in self.joints.items():
            v = r.variants[r.written]
            try:
                m = MotorModel.from_fit(r.fit, self.provenance(joint))
            except IdentificationError as exc:
                raise IdentificationError(
                    f"{self.log}: joint {joint}: the {r.written} fit is not a valid motor model ({exc}); too "
                    "little torque or velocity excitation? (expected a log from `servotau identify collect`)"
                ) from exc
            models[joint] = replace(m, metrics=FitMetrics(v.heldout_rms, v.heldout_overestimation, v.n_heldout))
        return MotorParameters(models)

    def to_dict(self) -> dict:
        s = self.settings
        return {
            "log": self.log, "backend": self.backend, "date": self.date,
            "settings": {"loss": s.loss.kind, "w": s.loss.w, "coulomb": s.coulomb, "two_stage": s.two_stage,
                         "dq_static": s.dq_static, "downsample": s.downsample, "holdout_block": s.holdout_block,
                         "holdout_every": s.holdout_every, "tau_shift": s.tau_shift},
            "units": {K_TAU: "rad/(N m)", K_V: "rad/(rad/s)", K_C: "rad", "rms": "rad"},
            "joints": {j: r.to_dict() for j, r in self.joints.items()},
            "notes": list(self.notes), "motor_file": self.motor_file,
        }

    def table(self) -> str:
        """Human-readable summary: one line per joint and fit."""
        lines = [f"{self.log} ({self.backend}, {self.date}); units: k_tau [rad/(N m)], k_v [rad/(rad/s)]",
                 f"{'joint':<12} {'fit':<22} {'k_tau':>10} {'k_v':>10} {'k_c':>9} {'over(held)':>10} "
                 f"{'rms(held)':>10}"]
        for joint, r in self.joints.items():
            for name, v in r.variants.items():
                c = v.coefficients
                kc = f"{c[K_C]:9.2e}" if K_C in c else f"{'-':>9}"
                mark = " *" if name == r.written else ""
                lines.append(f"{joint:<12} {name + mark:<22} {c[K_TAU]:10.3e} {c[K_V]:10.3e} {kc} "
                             f"{v.heldout_overestimation:10.3f} {v.heldout_rms:10.2e}")
            if r.reference is not None:
                c = r.reference["least_squares"]
                lines.append(f"{joint:<12} {'(ground truth, LS)':<22} {c[K_TAU]:10.3e} {c[K_V]:10.3e}")
        lines.append("* written to the motor file; over(held): fraction of held-out samples where |dq_err| is "
                     "over-estimated")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


# -- fitting ------------------------------------------------------------------------------------------------------
def _variant(name: str, fit: LinearFit | TwoStageFit, s: JointSamples) -> VariantResult:
    c = fit.coefficients
    model = c[K_TAU] * s.tau[s.held_out] + c[K_V] * s.dq[s.held_out] + c.get(K_C, 0.0) * np.sign(s.dq[s.held_out])
    target = s.dq_err[s.held_out]
    loss = str(fit.loss) if isinstance(fit, LinearFit) else f"two-stage ({fit.static.loss}, {fit.moving.loss})"
    return VariantResult(name, dict(c), loss, fit.rms, fit.overestimation_rate, fit.n_samples,
                         residual_rms(model, target), overestimation_rate(model, target), int(s.held_out.sum()))


def written_name(settings: FitSettings) -> str:
    """Name of the variant written to the motor file."""
    if settings.two_stage:
        return "two_stage"
    base = "asymmetric" if settings.loss.kind == "asymmetric" else "least_squares"
    return base + ("_coulomb" if settings.coulomb else "")


def fit_joint(s: JointSamples, settings: FitSettings) -> JointResult:
    """Every fit of one joint on its training samples; metrics on its held-out samples."""
    m = s.train
    if m.sum() < 30 or s.held_out.sum() < 10:
        raise IdentificationError(f"joint {s.joint}: {int(m.sum())} training and {int(s.held_out.sum())} held-out "
                                  "samples after downsampling: expected at least 30 and 10 (a longer log or a "
                                  "smaller downsample)")
    tau, dq, err = s.tau[m], s.dq[m], s.dq_err[m]
    what = f"joint {s.joint}"
    asym = settings.loss if settings.loss.kind == "asymmetric" else Loss.asymmetric(100.0)
    builders: dict[str, Callable[[], LinearFit | TwoStageFit]] = {
        "least_squares": lambda: fit_linear_model(tau, dq, err, what=what),
        "least_squares_coulomb": lambda: fit_linear_model(tau, dq, err, coulomb=True, what=what),
        "asymmetric": lambda: fit_linear_model(tau, dq, err, loss=asym, what=what),
        "two_stage": lambda: fit_two_stage(tau, dq, err, dq_static=settings.dq_static, coulomb=settings.coulomb,
                                           static_loss=settings.loss, moving_loss=settings.loss),
    }
    if settings.coulomb and settings.loss.kind == "asymmetric":
        builders["asymmetric_coulomb"] = lambda: fit_linear_model(tau, dq, err, coulomb=True, loss=asym, what=what)
    name = written_name(settings)
    fits, skipped = {}, {}
    for key, build in builders.items():
        try:
            fits[key] = build()
        except IdentificationError as exc:
            if key == name:
                raise
            skipped[key] = str(exc)  # a comparison fit the data cannot support (e.g. no static samples)
    reference = None
    if s.true_tau is not None:  # evaluation only, on the training samples that have ground truth
        ok = m & np.isfinite(s.true_tau) & np.isfinite(s.true_dq)
        args = (s.true_tau[ok], s.true_dq[ok], s.dq_err[ok])
        reference = {"least_squares": dict(fit_linear_model(*args, what=f"{what} (ground truth)").coefficients),
                     "least_squares_coulomb": dict(fit_linear_model(*args, coulomb=True,
                                                                    what=f"{what} (ground truth)").coefficients)}
    return JointResult(s.joint, {k: _variant(k, f, s) for k, f in fits.items()}, name, fits[name], reference,
                       skipped)


def fit_log(path: str | Path, joints: Sequence[str] | None = None, settings: FitSettings | None = None,
            estimator_config=None, progress: Callable[[str], None] | None = None) -> FitReport:
    """Read, estimate, align and fit (see module doc); the report of every joint."""
    settings = settings or FitSettings()
    aligned = load_aligned(path, joints, settings, estimator_config, progress)
    return fit_aligned(aligned, settings, progress)


def fit_aligned(aligned: AlignedLog, settings: FitSettings,
                progress: Callable[[str], None] | None = None) -> FitReport:
    """Fit every joint of an :class:`AlignedLog`."""
    results = {}
    for j, s in aligned.samples.items():
        if progress:
            progress(f"fitting {j}: {int(s.train.sum())} samples, {int(s.held_out.sum())} held out")
        results[j] = fit_joint(s, settings)
    notes = list(aligned.notes)
    for j, r in results.items():
        notes += [f"{j}: {k} fit skipped: {why}" for k, why in r.skipped.items()]
        c = r.variants[r.written].coefficients
        if not (c[K_TAU] > 0 and c[K_V] >= 0 and c.get(K_C, 0.0) >= 0):
            notes.append(f"{j}: the {r.written} fit has k_tau <= 0, k_v < 0 or k_c < 0: not a usable motor model")
    return FitReport(str(aligned.path.resolve()), aligned.backend, aligned.date, settings, results, tuple(notes))


def write_motor_file(report: FitReport, path: str | Path) -> Path:
    """Write the motor-parameter file (:class:`MotorParameters` format) with a header saying where it
    came from; ``metrics`` are those of the held-out samples."""
    p = report.motor_parameters().save_toml(path)
    s = report.settings
    header = [
        f"# Identified by `servotau identify fit` from {report.log} ({report.backend}, {report.date}).",
        f"# Fit written: {written_name(s)}" + (f", w = {s.loss.w:g}" if s.loss.w else "")
        + f"; downsample {s.downsample}; [metrics] are on held-out samples (1 block of {s.holdout_block:g} s in "
        f"{s.holdout_every}, not fitted).",
        "# Metrics on the fitted samples:",
        *(f"#   {j}: rms {r.variants[r.written].train_rms:.2e} rad, over-estimation rate "
          f"{r.variants[r.written].train_overestimation:.3f}, {r.variants[r.written].n_train} samples"
          for j, r in report.joints.items()),
    ]
    p.write_text("\n".join(header) + "\n" + p.read_text(encoding="utf-8"), encoding="utf-8")
    return p
