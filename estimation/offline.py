"""Off-line estimation on whole recordings: replay of the on-line estimator, and the non-causal estimator.

- :func:`replay` feeds recorded frames to a fresh :class:`TorqueEstimator`: the same code as on-line,
  hence bit-identical estimates (same delay).
- :func:`estimate_offline` filters whole signals with centred SG filters (no delay, every output at
  its own sample time) and runs the same per-sample dynamics: aligned ``q, dq, ddq, tau`` for the
  identification. Windows must be odd to centre on a sample: an even configured window ``N`` is
  used as ``N + 1``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from servotau.errors import EstimationError
from servotau.hal.types import STATUS_NAMES, RobotInfo, SensorFrame
from servotau.signal.savgol import savgol_centred

from .config import EstimatorConfig
from .dynamics import InverseDynamics
from .estimator import Estimate, TorqueEstimator
from .model import EstimatorModel

_ENC, _IMU = STATUS_NAMES.index("encoders"), STATUS_NAMES.index("imu")


def replay(frames: Iterable[SensorFrame], info: RobotInfo, config: EstimatorConfig | None = None,
           q_des: Sequence[np.ndarray] | None = None) -> list[Estimate]:
    """Run a fresh on-line estimator over recorded frames; one :meth:`Estimate.copy` per frame."""
    est = TorqueEstimator(info, config)
    if q_des is None:
        return [est.update(f).copy() for f in frames]
    return [est.update(f, qd).copy() for f, qd in zip(frames, q_des, strict=True)]


def frames_to_arrays(frames: Sequence[SensorFrame]) -> dict[str, np.ndarray]:
    """Stack the fields of recorded frames: ``time (T,)``, ``seq (T,)``, ``q (T, n)``,
    ``imu_angular_velocity (T, 3)``, ``imu_linear_acceleration (T, 3)``, ``wrenches (T, n_ft, 6)``,
    ``status (T, 6)``."""
    if not frames:
        raise EstimationError("frames_to_arrays: expected at least one frame")
    fields = ("q", "imu_angular_velocity", "imu_linear_acceleration", "wrenches", "status")
    out = {f: np.stack([getattr(fr, f) for fr in frames]) for f in fields}
    out["time"] = np.array([fr.time for fr in frames], dtype=float)
    out["seq"] = np.array([fr.seq for fr in frames], dtype=np.int64)
    return out


@dataclass(frozen=True)
class OfflineEstimate:
    """Non-causal estimates aligned with the input samples (no delay). Arrays have T rows."""

    time: np.ndarray  # [s] (T,) the input time stamps
    q: np.ndarray  # [rad] (T, n) HAL joint order
    dq: np.ndarray  # [rad/s] (T, n)
    ddq: np.ndarray  # [rad/s^2] (T, n)
    tau: np.ndarray  # [N m] (T, n), NaN where not tau_valid
    tau_valid: np.ndarray  # (T, n) bool: False near bad readings and within half a window of the ends
    wrenches: np.ndarray  # [N, N m] (T, n_ft, 6) compensated external wrenches (see Estimate.wrenches)
    base_wrench: np.ndarray  # [N, N m] (T, 6) unknown external wrench (see Estimate.base_wrench)
    valid: np.ndarray  # (T,) bool: every output of the sample valid


def _hold(x: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Replace bad samples (rows, or entries for a 2-D mask) by the last good one (the first good one
    before any). Columns without a good sample become 0."""
    x = np.array(x, dtype=float)
    flat = x.reshape(len(x), -1)
    mask = np.broadcast_to(bad.reshape(len(x), -1), flat.shape) if bad.ndim > 1 else \
        np.broadcast_to(bad[:, None], flat.shape)
    for c in range(flat.shape[1]):
        good = np.flatnonzero(~mask[:, c])
        if good.size == 0:
            flat[:, c] = 0.0
            continue
        idx = np.maximum.accumulate(np.where(~mask[:, c], np.arange(len(x)), -1))
        idx[idx < 0] = good[0]
        flat[:, c] = flat[idx, c]
    return flat.reshape(x.shape)


def _spread(bad: np.ndarray, half: int) -> np.ndarray:
    """Mark samples within ``half`` samples of a bad one, and the first/last ``half`` samples."""
    bad = np.asarray(bad, dtype=bool)
    out = bad.copy()
    for s in range(1, half + 1):
        out[s:] |= bad[:-s]
        out[:-s] |= bad[s:]
    out[:half] = True
    out[len(out) - half:] = True
    return out


def estimate_offline(time: np.ndarray, q: np.ndarray, imu_angular_velocity: np.ndarray,
                     imu_linear_acceleration: np.ndarray, wrenches: np.ndarray, info: RobotInfo,
                     config: EstimatorConfig | None = None, status: np.ndarray | None = None) -> OfflineEstimate:
    """Non-causal torque estimation on a whole recording (arrays as from :func:`frames_to_arrays`).

    Bad samples (status not OK or non-finite) are replaced by the last good one before filtering, as
    on-line, and flag every dependent output within half a window; so do the first and last half
    windows, where the centred window does not fit.

    Args:
        time: [s] (T,) uniformly sampled at ``info.period``.
        q: [rad] (T, n) encoder angles, HAL joint order.
        imu_angular_velocity: [rad/s] (T, 3); imu_linear_acceleration: [m/s^2] (T, 3).
        wrenches: [N, N m] (T, n_ft, 6) raw F/T readings (HAL convention; offsets removed here).
        info: The robot.
        config: Estimator settings (windows, orders, calibration; ``eval_at`` and ``align`` unused).
        status: (T, 6) per-frame status (default: all OK).
    """
    config = EstimatorConfig.from_toml() if config is None else config
    time = np.asarray(time, dtype=float)
    T = len(time)
    q = np.asarray(q, dtype=float)
    gyro = np.asarray(imu_angular_velocity, dtype=float)
    acc = np.asarray(imu_linear_acceleration, dtype=float)
    w = np.asarray(wrenches, dtype=float)
    n, nft = info.nq, len(info.ft_sensor_names)
    for name, arr, shape in (("q", q, (T, n)), ("imu_angular_velocity", gyro, (T, 3)),
                             ("imu_linear_acceleration", acc, (T, 3)), ("wrenches", w, (T, nft, 6))):
        if arr.shape != shape:
            raise EstimationError(f"{name} has shape {arr.shape}: expected {shape}")
    if T > 1 and not np.allclose(np.diff(time), info.period, rtol=1e-3, atol=1e-9):
        raise EstimationError(f"time: expected uniform samples every {info.period} s (a gap needs a new segment)")
    status = np.zeros((T, len(STATUS_NAMES)), dtype=np.uint8) if status is None else np.asarray(status)

    def odd(window: int) -> int:
        return window if window % 2 else window + 1

    enc_w, imu_w, ft_w = odd(config.encoders.window), odd(config.imu.window), odd(config.ft.window)
    if T < max(enc_w, imu_w, ft_w):
        raise EstimationError(f"recording of {T} samples: expected at least one window ({max(enc_w, imu_w, ft_w)})")
    enc_bad = ~np.isfinite(q) | (status[:, _ENC] != 0)[:, None]
    imu_bad = ~(np.isfinite(gyro).all(1) & np.isfinite(acc).all(1)) | (status[:, _IMU] != 0)
    ft_bad = ~np.isfinite(w).all(2) | (status[:, 2:2 + nft] != 0)
    q_h = _hold(q, enc_bad)
    gyro_h = _hold(gyro, imu_bad) - config.gyro_bias
    acc_h = _hold(acc, imu_bad)
    w_h = _hold(w.reshape(T, -1), np.repeat(ft_bad, 6, axis=1)).reshape(T, nft, 6) - config.ft_offsets
    dt = info.period
    o = config.encoders.order
    qf = savgol_centred(q_h, enc_w, o, dt, 0)
    dqf = savgol_centred(q_h, enc_w, o, dt, 1)
    ddqf = savgol_centred(q_h, enc_w, o, dt, 2)
    gf = savgol_centred(gyro_h, imu_w, config.imu.order, dt, 0)
    dgf = (savgol_centred(gyro_h, imu_w, config.imu.order, dt, 1) if config.angular_acceleration == "savgol"
           else np.zeros_like(gf))
    af = savgol_centred(acc_h, imu_w, config.imu.order, dt, 0)
    wf = savgol_centred(w_h.reshape(T, -1), ft_w, config.ft.order, dt, 0).reshape(T, nft, 6)

    robot = EstimatorModel(info, config)
    dyn = InverseDynamics(robot, config.angular_acceleration)
    tau = np.empty((T, n))
    wrench_out = np.empty((T, nft, 6))
    base = np.empty((T, 6))
    for k in range(T):
        dyn.compute(qf[k], dqf[k], ddqf[k], gf[k], dgf[k], af[k], wf[k])
        tau[k] = dyn.tau
        wrench_out[k] = dyn.wrenches
        base[k] = dyn.base_wrench

    dep_enc, dep_ft, ft_dep_enc = robot.dependencies()
    enc_flag = np.stack([_spread(enc_bad[:, j], enc_w // 2) for j in range(n)], axis=1)
    imu_flag = _spread(imu_bad, imu_w // 2)
    ft_flag = np.stack([_spread(ft_bad[:, s], ft_w // 2) for s in range(nft)], axis=1)
    tau_bad = (enc_flag.astype(int) @ dep_enc.T.astype(int) > 0) | (ft_flag.astype(int) @ dep_ft.T.astype(int) > 0)
    tau_bad |= imu_flag[:, None]
    w_bad = ft_flag | (enc_flag.astype(int) @ ft_dep_enc.T.astype(int) > 0) | imu_flag[:, None]
    tau[tau_bad] = np.nan
    wrench_out[w_bad] = np.nan
    valid = ~(tau_bad.any(1) | w_bad.any(1))
    base[~valid] = np.nan
    return OfflineEstimate(time=time, q=qf, dq=dqf, ddq=ddqf, tau=tau, tau_valid=~tau_bad, wrenches=wrench_out,
                           base_wrench=base, valid=valid)
