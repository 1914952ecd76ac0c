"""Off-line calibration of the sensors and of the bodies beyond the F/T sensors (paper section 2.2).

- F/T offsets: in a phase where an end effector touches nothing (the hanging robot's feet, free
  hands), the compensated external wrench must be zero, so the wrench the estimator computes with
  zero offsets *is* the offset: ``offset = measured - predicted``, with ``predicted = -(I (a - g) +
  v x* I v)`` the wrench the body beyond the sensor exerts on it.
- Gyro bias: the mean gyro reading while the robot does not rotate.
- Inertial parameters beyond a sensor (mass, CoM, optionally inertia): from F/T readings in several
  orientations (static or slow). At rest the sensor reads ``f = -[m s; m c x s] + offset`` where ``s``
  is the sensor's specific force (``-g`` in the sensor frame); in motion the Newton-Euler regressor
  of the body replaces it. Linear in ``(m, m c, [I], offset)``: least squares.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from servotau.errors import EstimationError
from servotau.hal.types import STATUS_OK, RobotInfo, SensorFrame

from .config import EstimatorConfig
from .estimator import TorqueEstimator


def calibrate_ft_offsets(frames: Iterable[SensorFrame], info: RobotInfo, config: EstimatorConfig | None = None,
                         sensors: Iterable[str] | None = None) -> np.ndarray:
    """F/T offsets [N, N m] (n_ft, 6) from frames where the end effectors of ``sensors`` touch nothing.

    Args:
        frames: Consecutive frames (one per period) of a no-contact phase for ``sensors``; the first
            filter window is used only to fill the filters.
        info: The robot.
        config: Estimator settings (its offsets are ignored; default config/estimation.toml).
        sensors: HAL names of the sensors to calibrate (default: all); the other rows keep the
            offsets of ``config``.

    Returns:
        Offsets in ``info.ft_sensor_names`` row order, to pass to
        :meth:`EstimatorConfig.with_calibration` or :meth:`TorqueEstimator.set_ft_offsets`.
    """
    config = EstimatorConfig.from_toml() if config is None else config
    zero = np.zeros_like(config.ft_offsets)
    est = TorqueEstimator(info, config.with_calibration(ft_offsets=zero))
    average = FtOffsetAverage(info, zero)
    for frame in frames:
        average.add(est.update(frame))
    return average.offsets(config, sensors)


class FtOffsetAverage:
    """:func:`calibrate_ft_offsets` tick by tick, from the estimates of the estimator already running (no second
    pass over the frames, so no stall at the end of a settle phase).

    The estimator subtracts its offsets before its linear filters and compensation, so the wrench it would
    estimate with zero offsets is its estimate plus the offsets it uses (``offsets_in_use``, constant while
    averaging)::

        average = FtOffsetAverage(info, estimator.ft_offsets)
        for frame in settle_frames: average.add(estimator.update(frame))
        estimator.set_ft_offsets(average.offsets(estimator.config))
    """

    def __init__(self, info: RobotInfo, offsets_in_use: np.ndarray):
        self.info = info
        self._in_use = np.array(offsets_in_use, dtype=float)  # [N, N m] (n_ft, 6)
        self._total = np.zeros_like(self._in_use)
        self._count = np.zeros(len(self._in_use))

    def add(self, estimate) -> None:
        """One tick's estimate (``wrenches`` (n_ft, 6) [N, N m], ``wrenches_valid`` (n_ft,))."""
        ok = estimate.wrenches_valid
        self._total[ok] += estimate.wrenches[ok] + self._in_use[ok]
        self._count[ok] += 1

    def offsets(self, config: EstimatorConfig, sensors: Iterable[str] | None = None) -> np.ndarray:
        """Offsets (n_ft, 6) [N, N m] as :func:`calibrate_ft_offsets` returns them (``sensors``: the rows
        calibrated, default all; the others keep ``config.ft_offsets``)."""
        names = list(self.info.ft_sensor_names if sensors is None else sensors)
        offsets = np.array(config.ft_offsets, dtype=float)
        for s in names:
            r = self.info.ft_index(s)
            if self._count[r] < 1:
                raise EstimationError(f'F/T sensor "{s}": no valid estimate in the frames: expected more than '
                                      f"one filter window ({config.ft.window} samples) of good readings")
            offsets[r] = self._total[r] / self._count[r]
        return offsets


def calibrate_gyro_bias(frames: Iterable[SensorFrame]) -> np.ndarray:
    """Gyro bias [rad/s] (3,), IMU frame: the mean reading of frames where the robot does not rotate."""
    total, count = np.zeros(3), 0
    for frame in frames:
        w = frame.imu_angular_velocity
        if frame.is_ok("imu") and np.all(np.isfinite(w)):
            total += w
            count += 1
    if count == 0:
        raise EstimationError("calibrate_gyro_bias: no valid IMU reading in the frames")
    return total / count


@dataclass(frozen=True)
class Payload:
    """Inertial parameters of the bodies beyond one F/T sensor, identified from its readings."""

    mass: float  # [kg]
    com: np.ndarray  # [m] (3,) centre of mass in the sensor frame
    inertia: np.ndarray | None  # [kg m^2] (3, 3) rotational inertia about the sensor origin, if identified
    offset: np.ndarray  # [N, N m] (6,) sensor offset identified with them
    residual_rms: float  # [N or N m] RMS of the least-squares residual
    n_samples: int


def identify_payload(acceleration: np.ndarray, wrenches: np.ndarray, velocity: np.ndarray | None = None,
                     known: np.ndarray | None = None, inertia: bool = False,
                     min_conditioning: float = 1e-3) -> Payload:
    """Mass, CoM (optionally rotational inertia) and offset of the body beyond an F/T sensor, least squares.

    Newton-Euler of the body beyond the sensor, in the sensor frame, with nothing touching it::

        wrenches + known = -Y(v, a) pi + offset,   pi = [m, m c, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz]

    where ``Y`` is Pinocchio's body regressor (``I a + v x* I v = Y pi``). At rest ``Y pi`` reduces to
    ``[m s; m c x s]``. Without ``inertia`` the rotational-inertia columns are dropped (slow motions).

    Args:
        acceleration: (T, 3) specific force of the sensor origin [m/s^2] (static data,
            :meth:`InverseDynamics.ft_specific_force`), or (T, 6) spatial acceleration of the sensor
            frame with gravity folded in (:meth:`InverseDynamics.ft_motion`), sensor frame.
        wrenches: [N, N m] (T, 6) measured wrenches (HAL convention, offsets *not* removed).
        velocity: [m/s, rad/s] (T, 6) spatial velocity of the sensor frame (None: at rest).
        known: [N, N m] (T, 6) optional inertial wrench of bodies whose parameters are known and not
            identified (e.g. the gripper, :meth:`InverseDynamics.distal_joint_wrench`); added to ``wrenches``.
        inertia: Also identify the rotational inertia (needs rotations fast enough to excite it).
        min_conditioning: Smallest accepted ratio of the extreme singular values of the (column-scaled)
            regressor: the orientations must differ enough to separate the CoM from the torque offset.

    Returns:
        The identified :class:`Payload`.
    """
    acc = np.asarray(acceleration, dtype=float)
    w = np.asarray(wrenches, dtype=float)
    T = len(w)
    if acc.ndim != 2 or acc.shape[0] != T or acc.shape[1] not in (3, 6) or w.shape != (T, 6):
        raise EstimationError(f"acceleration {acc.shape} and wrenches {w.shape}: expected (T, 3 or 6) and (T, 6)")
    if acc.shape[1] == 3:
        acc = np.concatenate([acc, np.zeros((T, 3))], axis=1)
    vel = np.zeros((T, 6)) if velocity is None else np.asarray(velocity, dtype=float)
    if known is not None:
        w = w + np.asarray(known, dtype=float)
    if vel.shape != (T, 6) or not (np.all(np.isfinite(acc)) and np.all(np.isfinite(vel)) and np.all(np.isfinite(w))):
        raise EstimationError("identify_payload: expected finite samples of matching shapes (drop the invalid ones)")
    n_par = 10 if inertia else 4
    A = np.zeros((6 * T, n_par + 6))
    for k in range(T):
        Y = pin.bodyRegressor(pin.Motion(vel[k]), pin.Motion(acc[k]))
        A[6 * k : 6 * k + 6, :n_par] = -Y[:, :n_par]
        A[6 * k : 6 * k + 6, n_par:] = np.eye(6)
    b = w.reshape(-1)
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    sv = np.linalg.svd(A / scale, compute_uv=False)
    if T < 3 or sv[-1] < min_conditioning * sv[0]:
        raise EstimationError(
            "identify_payload: the data do not excite every parameter (conditioning "
            f"{sv[-1] / sv[0]:.2g} < {min_conditioning}): expected samples in at least 3 orientations well apart"
            + (" and fast enough rotations for the inertia" if inertia else "")
        )
    x = np.linalg.lstsq(A / scale, b, rcond=None)[0] / scale
    mass = float(x[0])
    if not mass > 0.0:
        raise EstimationError(f"identify_payload: identified mass {mass:.4g} kg: expected > 0 (check the data)")
    rot = None
    if inertia:
        xx, xy, yy, xz, yz, zz = x[4:10]
        rot = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    residual = b - A @ x
    return Payload(mass=mass, com=x[1:4] / mass, inertia=rot, offset=x[n_par:].copy(),
                   residual_rms=float(np.sqrt(np.mean(residual**2))), n_samples=T)


def payload_samples(frames: Iterable[SensorFrame], info: RobotInfo, sensor: str,
                    config: EstimatorConfig | None = None, max_joint_speed: float = 0.01,
                    max_base_rate: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Collect ``(velocity, acceleration, wrenches, known)`` of one sensor for :func:`identify_payload`.

    Runs the estimator over the frames (its offsets ignored) and keeps the valid ticks where every
    joint turns slower than ``max_joint_speed`` and the base slower than ``max_base_rate`` [rad/s]
    (slow rotations: the rotational inertia, not identified by default, then matters little; the
    translational effects of the motion are in the regressor). ``wrenches`` are the filtered readings
    without offset removal and ``known`` the modelled inertial wrench of the bodies behind a joint beyond
    the sensor (the gripper), all in the sensor frame.
    """
    config = EstimatorConfig.from_toml() if config is None else config
    est = TorqueEstimator(info, config.with_calibration(ft_offsets=np.zeros_like(config.ft_offsets)))
    r = info.ft_index(sensor)
    vel, acc, out_w, out_k = [], [], [], []
    v6, a6, k6 = (np.zeros((len(info.ft_sensor_names), 6)) for _ in range(3))
    for frame in frames:
        e = est.update(frame)
        if not (e.wrenches_valid[r] and frame.status[2 + r] == STATUS_OK):
            continue
        if np.max(np.abs(e.dq)) > max_joint_speed or np.max(np.abs(e.base_angular_velocity)) > max_base_rate:
            continue
        dyn = est.dynamics
        dyn.ft_motion(v6, a6)
        vel.append(v6[r].copy())
        acc.append(a6[r].copy())
        out_w.append(e.wrenches[r] - dyn.beyond_wrench[r])  # the filtered measurement
        out_k.append(dyn.distal_joint_wrench(k6)[r].copy())
    if not vel:
        raise EstimationError(f'payload_samples: no valid slow tick (joints < {max_joint_speed} rad/s, base < '
                              f'{max_base_rate} rad/s) for sensor "{sensor}"')
    return np.array(vel), np.array(acc), np.array(out_w), np.array(out_k)
