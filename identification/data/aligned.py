"""A log's aligned samples: ``dq_err``, ``dq`` and ``tau`` of each joint, row by row (paper section 3).

1. **Read** the project's Parquet log (:func:`~.tables.open_log`): sensors, the commands ``q_des`` and, if
   present, the phases written by ``servotau identify collect``.
2. **Estimate** ``q, dq, ddq, tau`` with the non-causal estimator
   (:func:`~servotau.estimation.estimate_offline`: centred SG filters, every output at its own sample
   time, no delay), on each contiguous segment of the log (:func:`~.segments.segments`: ``seq`` steps by
   one, the time by one period), after calibrating the F/T offsets and the gyro bias on the ``settle`` phase
   (feet free, robot still). The ground truth a simulated log may carry is never used for the estimates; it
   is aligned the same way for evaluation only (:attr:`JointSamples.true_tau`).
3. **Align**: ``dq_err[k] = q_des[k] - q[k]`` (the command answering frame ``k`` and the encoder
   reading it answered, as the servo sees them), ``dq[k]`` the estimate at frame ``k``, and
   ``tau[k + tau_shift]`` (:func:`~.segments.shift`, NaN past a segment's end): the servo's current of period
   ``k`` comes from ``q_des[k] - q[k]``, and the torque of period ``k`` is what the sensors of frame ``k + 1``
   see (zero-order hold), so ``tau_shift = 1`` tick.
4. **Split** (:func:`~.folds.holdout_split`): blocks of ``holdout_block`` seconds, every ``holdout_every``-th
   held out; then every ``downsample``-th valid sample of each set.

Both the paper's pipeline (:mod:`servotau.identification.pipeline`) and the workbench (a log without
``est/tau/<joint>``, :mod:`servotau.identification.workbench.data`) read a log through :func:`load_aligned`.
"""

from __future__ import annotations

import datetime
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servotau.errors import EstimationError, IdentificationError

from ..plan import PHASES, FitSettings, check_joints
from ..session import META_BACKEND, META_DATE, META_JOINTS, PHASE_COLUMN
from .folds import holdout_split
from .segments import segments, shift
from .tables import open_log

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


# -- reading and aligning -------------------------------------------------------------------------------------
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

    settings = settings or FitSettings()
    say = progress or (lambda _m: None)
    path = Path(path)
    reader = open_log(path)
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
    for a, b in segments(t_all, info.period, seq=cols["seq"]):
        if b - a < min_rows:
            notes.append(f"rows [{a}, {b}) skipped: a segment of {b - a} ticks (expected >= {min_rows})")
            continue
        rows = np.arange(a, b)
        say(f"estimating q, dq, tau on rows [{a}, {b}) ({(b - a) * info.period:.1f} s)")
        arr = _arrays(cols, info, rows)
        est = estimate_offline(arr["time"], arr["q"], arr["imu_angular_velocity"], arr["imu_linear_acceleration"],
                               arr["wrenches"], info, config, status=arr["status"])
        tau[a:b] = shift(est.tau[:, idx], settings.tau_shift)  # NaN where not tau_valid
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
        train, held = holdout_split(t_all, valid, settings.holdout_block, settings.holdout_every,
                                    settings.downsample)
        true_tau = true_dq = None
        if has_truth:  # evaluation only: the torque of period k is the truth of row k + 1 (zero-order hold)
            true_tau = shift(cols[f"true/tau/{j}"], 1)
            true_dq = cols[f"true/dq/{j}"]
        samples[j] = JointSamples(j, t_all, dq_err, dq[:, c], tau[:, c], train, held,
                                  None if phase is None else phase, true_tau, true_dq)
    backend = reader.metadata.get(META_BACKEND) or reader.metadata.get("servotau.source", "unknown")
    date = reader.metadata.get(META_DATE) or datetime.datetime.fromtimestamp(
        path.stat().st_mtime, datetime.UTC).isoformat(timespec="seconds") + " (file time)"
    return AlignedLog(path, info, samples, backend, date, tuple(notes))
