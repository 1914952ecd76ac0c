"""From a recorded log to identified motor parameters (paper section 3), off-line.

1. **Read** the project's Parquet log (:class:`~servotau.hal.log.LogReader`): sensors, the commands
   ``q_des`` and, if present, the phases written by ``servotau identify collect``.
2. **Estimate** ``q, dq, ddq, tau`` with the non-causal estimator
   (:func:`~servotau.estimation.estimate_offline`: centred SG filters, every output at its own sample
   time, no delay), on each contiguous segment of the log, after calibrating the F/T offsets and the
   gyro bias on the ``settle`` phase (feet free, robot still). The ground truth a simulated log may
   carry is never used for the fit; it only gives an evaluation reference (:attr:`JointResult.reference`).
3. **Align**: ``dq_err[k] = q_des[k] - q[k]`` (the command answering frame ``k`` and the encoder
   reading it answered, as the servo sees them), ``dq[k]`` the estimate at frame ``k``, and
   ``tau[k + tau_shift]``: the servo's current of period ``k`` comes from ``q_des[k] - q[k]``, and the
   torque of period ``k`` is what the sensors of frame ``k + 1`` see (zero-order hold), so
   ``tau_shift = 1`` tick.
4. **Split**: blocks of ``holdout_block`` seconds, every ``holdout_every``-th held out (contiguous
   blocks, not random samples: neighbouring samples are nearly equal); then keep every
   ``downsample``-th valid sample of each set.
5. **Fit** per joint: least squares with and without Coulomb (eq. 7), the asymmetric penalty (eq. 8,
   Newton), the two-stage fit (section 3.3.1); metrics on the fitted and on the held-out samples.
"""

from __future__ import annotations

import datetime
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from servotau.actuator import FitMetrics, MotorModel, MotorParameters
from servotau.actuator.loss import Loss
from servotau.errors import EstimationError, HalError, IdentificationError

from .fit import fit_linear_model
from .linear_fit import LinearFit
from .metrics import overestimation_rate, residual_rms
from .plan import PHASES, FitSettings, check_joints
from .regressors import K_C, K_TAU, K_V
from .session import META_BACKEND, META_DATE, META_JOINTS, PHASE_COLUMN
from .two_stage import TwoStageFit, fit_two_stage

MIN_SECONDS = 1.0  # [s] shortest usable log after the estimator's edges


@dataclass(frozen=True, eq=False)
class JointSamples:
    """Aligned samples of one joint (all valid samples, 1 per tick; the splits are masks).

    ``tau`` and ``dq`` are the estimator's; ``true_tau`` and ``true_dq`` the simulator's ground truth
    (None for a real robot), aligned the same way, for evaluation only.
    """

    joint: str
    t: np.ndarray  # [s] time of frame k
    dq_err: np.ndarray  # [rad] q_des[k] - q[k]
    dq: np.ndarray  # [rad/s]
    tau: np.ndarray  # [N m]
    train: np.ndarray  # bool: fitted (after downsampling)
    held_out: np.ndarray  # bool: held-out (after downsampling)
    phase: np.ndarray | None = None  # index in PHASES, or None if the log has no phases
    true_tau: np.ndarray | None = None
    true_dq: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class AlignedLog:
    """Every joint's aligned samples and where they came from."""

    path: Path
    info: object  # RobotInfo
    samples: dict[str, JointSamples]
    backend: str
    date: str
    notes: tuple[str, ...] = ()

    @property
    def has_truth(self) -> bool:
        return all(s.true_tau is not None for s in self.samples.values())


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


# -- reading and aligning -------------------------------------------------------------------------------------
def _segments(seq: np.ndarray, t: np.ndarray, period: float) -> list[tuple[int, int]]:
    """``[start, stop)`` row ranges of consecutive ticks."""
    if len(seq) == 0:
        return []
    breaks = np.flatnonzero((np.diff(seq) != 1) | ~np.isclose(np.diff(t), period, rtol=1e-3, atol=1e-9)) + 1
    edges = [0, *breaks.tolist(), len(seq)]
    return [(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def _arrays(cols: dict, info, rows: np.ndarray) -> dict[str, np.ndarray]:
    """Sensor arrays of ``rows`` as :func:`~servotau.estimation.frames_to_arrays` gives them."""
    from servotau.hal.log import WRENCH_AXES
    from servotau.hal.types import STATUS_NAMES

    return {
        "time": cols["t"][rows], "seq": cols["seq"][rows],
        "q": np.column_stack([cols[f"q/{j}"][rows] for j in info.joint_names]),
        "imu_angular_velocity": np.column_stack([cols[f"imu/gyro_{a}"][rows] for a in "xyz"]),
        "imu_linear_acceleration": np.column_stack([cols[f"imu/acc_{a}"][rows] for a in "xyz"]),
        "wrenches": np.stack([np.column_stack([cols[f"ft/{s}/{a}"][rows] for a in WRENCH_AXES])
                              for s in info.ft_sensor_names], axis=1),
        "status": np.column_stack([cols[f"status/{s}"][rows] for s in STATUS_NAMES]).astype(np.uint8),
    }


def _frames(cols: dict, info, rows: np.ndarray) -> list:
    from servotau.hal.types import SensorFrame

    a = _arrays(cols, info, rows)
    return [SensorFrame(time=float(a["time"][i]), seq=int(a["seq"][i]), q=a["q"][i],
                        imu_angular_velocity=a["imu_angular_velocity"][i],
                        imu_linear_acceleration=a["imu_linear_acceleration"][i], wrenches=a["wrenches"][i],
                        status=a["status"][i]) for i in range(len(rows))]


def _calibrated_config(cols: dict, info, config, phase: np.ndarray | None, notes: list[str]):
    """Estimator config with F/T offsets and gyro bias measured on the settle phase (if the log has one)."""
    from servotau.estimation import calibrate_ft_offsets, calibrate_gyro_bias

    if phase is None:
        notes.append("no ident/phase column: F/T offsets and gyro bias from config/estimation.toml (not calibrated)")
        return config
    rows = np.flatnonzero(phase == PHASES.index("settle"))
    if len(rows) < 2 * config.ft.window or np.any(np.diff(rows) != 1):
        notes.append(f"settle phase of {len(rows)} ticks: too short for calibration (expected >= "
                     f"{2 * config.ft.window} consecutive): F/T offsets and gyro bias from config/estimation.toml")
        return config
    rows = rows[len(rows) // 4:]  # the robot settles in the first quarter
    frames = _frames(cols, info, rows)
    try:
        offsets = calibrate_ft_offsets(frames, info, config)
        bias = calibrate_gyro_bias(frames)
    except EstimationError as exc:
        notes.append(f"calibration on the settle phase failed ({exc}): using config/estimation.toml")
        return config
    notes.append(f"F/T offsets and gyro bias calibrated on {len(rows)} settle ticks")
    return config.with_calibration(ft_offsets=offsets, gyro_bias=bias)


def _shift(x: np.ndarray, k: int) -> np.ndarray:
    """``out[i] = x[i + k]`` (NaN past the end)."""
    if k == 0:
        return x.copy()
    out = np.full_like(x, np.nan)
    out[:-k] = x[k:]
    return out


def _splits(t: np.ndarray, valid: np.ndarray, settings: FitSettings) -> tuple[np.ndarray, np.ndarray]:
    block = np.floor((t - t[0]) / settings.holdout_block).astype(np.int64)
    held = block % settings.holdout_every == settings.holdout_every - 1
    train, test = np.zeros(len(t), bool), np.zeros(len(t), bool)
    for mask, out in ((valid & ~held, train), (valid & held, test)):
        idx = np.flatnonzero(mask)
        out[idx[:: settings.downsample]] = True
    return train, test


def load_aligned(path: str | Path, joints: Sequence[str] | None = None, settings: FitSettings | None = None,
                 estimator_config=None, progress: Callable[[str], None] | None = None) -> AlignedLog:
    """Read a log, estimate and align ``dq_err``, ``dq`` and ``tau`` of ``joints`` (see module doc).

    Args:
        path: Parquet log with ``q_des/<joint>`` columns.
        joints: Joints to align (default: the swept joints recorded by collect, else every joint whose
            ``q_des`` moved).
        settings: Split, downsampling and alignment settings (default :class:`FitSettings`).
        estimator_config: :class:`~servotau.estimation.EstimatorConfig` (default config/estimation.toml).
        progress: Called with a line per step.

    Raises:
        IdentificationError: Missing or unreadable log, missing columns, unknown joint, too short log,
            a joint without any valid sample; each names the file, the field and what was expected.
    """
    from servotau.estimation import EstimatorConfig, estimate_offline
    from servotau.hal.log import LogReader

    settings = settings or FitSettings()
    say = progress or (lambda _m: None)
    path = Path(path)
    if not path.exists() and not Path(str(path) + ".parts").exists():
        raise IdentificationError(f"{path}: no such log file: expected a Parquet log from `servotau identify collect`")
    try:
        reader = LogReader(path)
    except HalError as exc:
        raise IdentificationError(f"{path}: cannot read the log ({exc}): expected a servotau Parquet log") from exc
    except Exception as exc:  # pyarrow's errors for a file that is not Parquet
        raise IdentificationError(f"{path}: not a Parquet log ({type(exc).__name__}: {exc})") from exc
    info, cols = reader.info, reader.columns
    missing_qdes = [j for j in info.joint_names if f"q_des/{j}" not in cols]
    if missing_qdes:
        raise IdentificationError(f"{path}: no column 'q_des/{missing_qdes[0]}': expected the commanded angles "
                                  "q_des/<joint> of every joint (a log written with commands, e.g. by "
                                  "`servotau identify collect`)")
    if joints is None:
        meta = reader.metadata.get(META_JOINTS)
        joints = json.loads(meta) if meta else [j for j in info.joint_names
                                                if np.nanmax(cols[f"q_des/{j}"], initial=-np.inf)
                                                - np.nanmin(cols[f"q_des/{j}"], initial=np.inf) > 1e-3]
        if not joints:
            raise IdentificationError(f"{path}: no swept joint recorded and no q_des/<joint> that moves: expected "
                                      "--joints or a log from `servotau identify collect`")
    joints = check_joints(joints, info.joint_names, f"{path}: joints to fit")
    config = estimator_config or EstimatorConfig.from_toml()
    window = max(config.encoders.window, config.imu.window, config.ft.window) | 1
    min_rows = window + int(math.ceil(MIN_SECONDS / info.period))
    n = len(reader)
    if n < min_rows:
        raise IdentificationError(f"{path}: {n} rows ({n * info.period:.3f} s): expected at least {min_rows} rows "
                                  f"({MIN_SECONDS:g} s plus one estimator window of {window} samples)")
    notes: list[str] = []
    for j in joints:
        if not np.isfinite(cols[f"q_des/{j}"]).any():
            raise IdentificationError(f"{path}: column 'q_des/{j}' is NaN in every row: expected the commands "
                                      "sent to the joint (NaN = no command / servo off)")
    phase = cols.get(PHASE_COLUMN)
    config = _calibrated_config(cols, info, config, phase, notes)
    idx = [info.joint_index(j) for j in joints]
    t_all = cols["t"]
    tau = np.full((n, len(joints)), np.nan)
    dq = np.full((n, len(joints)), np.nan)
    for a, b in _segments(cols["seq"], t_all, info.period):
        if b - a < min_rows:
            notes.append(f"rows [{a}, {b}) skipped: a segment of {b - a} ticks (expected >= {min_rows})")
            continue
        rows = np.arange(a, b)
        say(f"estimating q, dq, tau on rows [{a}, {b}) ({(b - a) * info.period:.1f} s)")
        arr = _arrays(cols, info, rows)
        est = estimate_offline(arr["time"], arr["q"], arr["imu_angular_velocity"], arr["imu_linear_acceleration"],
                               arr["wrenches"], info, config, status=arr["status"])
        tau[a:b] = _shift(est.tau[:, idx], settings.tau_shift)  # NaN where not tau_valid
        dq[a:b] = est.dq[:, idx]
        dq[a:b][~est.tau_valid[:, idx]] = np.nan
    has_truth = all(f"true/tau/{j}" in cols and f"true/dq/{j}" in cols for j in joints)
    samples = {}
    for c, j in enumerate(joints):
        q, q_des = cols[f"q/{j}"], cols[f"q_des/{j}"]
        dq_err = q_des - q
        valid = np.isfinite(dq_err) & np.isfinite(tau[:, c]) & np.isfinite(dq[:, c])
        if not valid.any():
            raise IdentificationError(f"{path}: joint {j}: no row with a finite q_des/{j}, q/{j} and estimated tau "
                                      "(NaN-only data, or sensors invalid everywhere): expected valid samples")
        train, held = _splits(t_all, valid, settings)
        true_tau = true_dq = None
        if has_truth:  # evaluation only: the torque of period k is the truth of row k + 1 (zero-order hold)
            true_tau = _shift(cols[f"true/tau/{j}"], 1)
            true_dq = cols[f"true/dq/{j}"]
        samples[j] = JointSamples(j, t_all, dq_err, dq[:, c], tau[:, c], train, held,
                                  None if phase is None else phase, true_tau, true_dq)
    backend = reader.metadata.get(META_BACKEND) or reader.metadata.get("servotau.source", "unknown")
    date = reader.metadata.get(META_DATE) or datetime.datetime.fromtimestamp(
        path.stat().st_mtime, datetime.UTC).isoformat(timespec="seconds") + " (file time)"
    return AlignedLog(path, info, samples, backend, date, tuple(notes))


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
