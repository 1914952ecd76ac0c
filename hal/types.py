"""Data that crosses the hardware abstraction layer.

Everything here is what a real HRP-2 gives: encoder angles, a chest IMU and four 6-axis F/T
sensors, stamped with robot time. Nothing here comes from the simulator's ground truth.

Conventions:
- Joint arrays are ordered as :attr:`RobotInfo.joint_names`; address joints by name with
  :meth:`RobotInfo.joint_index` or :meth:`SensorFrame.position`, never by a bare index taken
  from another library.
- Wrenches are ``[fx, fy, fz, tx, ty, tz]`` in [N] and [N m], expressed in the sensor frame at
  the sensor origin. Sign: the wrench that the *distal* side (hand or foot, plus whatever touches
  it) exerts on the *proximal* side (the arm or leg). A robot standing still reads fz > 0 at both
  ankles (about half its weight each).
- The accelerometer reads specific force (acceleration minus gravity) in the IMU frame: an IMU
  at rest and upright reads about ``[0, 0, +9.81]`` [m/s^2].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from servotau.errors import HalError

FT_SENSOR_NAMES: tuple[str, ...] = ("right_ankle", "left_ankle", "right_wrist", "left_wrist")
"""The four F/T sensors, in the row order of :attr:`SensorFrame.wrenches`."""

STATUS_NAMES: tuple[str, ...] = ("encoders", "imu", *FT_SENSOR_NAMES)
"""Entries of :attr:`SensorFrame.status`."""

STATUS_OK = 0
STATUS_STALE = 1  # the reading was not refreshed this tick
STATUS_INVALID = 2  # NaN, inf or an out-of-range value
STATUS_SATURATED = 3  # the sensor reached its measurement range


@dataclass(frozen=True)
class RobotInfo:
    """Static description of a robot behind a HAL backend."""

    name: str
    joint_names: tuple[str, ...]
    q_min: np.ndarray  # [rad] lower joint limits, in joint_names order
    q_max: np.ndarray  # [rad] upper joint limits
    period: float  # [s] control period (HRP-2: 1e-3)
    model_path: str  # MJCF file of the robot model (the estimator's and controller's model)
    ft_sensor_names: tuple[str, ...] = FT_SENSOR_NAMES
    max_position_error: float = 0.1  # [rad] the robot cuts its servos past this |q_des - q|
    _index: dict = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        n = len(self.joint_names)
        if len(set(self.joint_names)) != n:
            raise HalError(f"RobotInfo.joint_names has duplicates: {self.joint_names}")
        for name in ("q_min", "q_max"):
            arr = np.asarray(getattr(self, name), dtype=float)
            if arr.shape != (n,):
                raise HalError(f"RobotInfo.{name} has shape {arr.shape}: expected ({n},)")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if not self.period > 0:
            raise HalError(f"RobotInfo.period = {self.period}: expected > 0 [s]")
        object.__setattr__(self, "_index", {j: i for i, j in enumerate(self.joint_names)})

    @property
    def nq(self) -> int:
        """Number of actuated joints."""
        return len(self.joint_names)

    def joint_index(self, name: str) -> int:
        """Position of joint ``name`` in this robot's joint arrays."""
        try:
            return self._index[name]
        except KeyError:
            raise HalError(
                f'joint "{name}" is not a joint of {self.name}: expected one of {list(self.joint_names)}'
            ) from None

    def ft_index(self, sensor: str) -> int:
        """Row of F/T sensor ``sensor`` in :attr:`SensorFrame.wrenches`."""
        try:
            return self.ft_sensor_names.index(sensor)
        except ValueError:
            raise HalError(f'"{sensor}" is not an F/T sensor: expected one of {list(self.ft_sensor_names)}') from None


@dataclass(frozen=True)
class SensorFrame:
    """One atomic reading of all the robot's sensors at one robot tick."""

    time: float  # [s] robot time (sim time in simulation; never wall clock)
    seq: int  # tick sequence number, +1 per period
    q: np.ndarray  # [rad] encoder angles, (nq,) in RobotInfo.joint_names order
    imu_angular_velocity: np.ndarray  # [rad/s] gyroscope, (3,) in the IMU frame
    imu_linear_acceleration: np.ndarray  # [m/s^2] accelerometer specific force, (3,) in the IMU frame
    wrenches: np.ndarray  # [N, N m] (4, 6) one row per F/T sensor, each in its sensor frame
    status: np.ndarray  # (6,) uint8 per STATUS_NAMES: STATUS_OK, _STALE, _INVALID or _SATURATED

    def is_ok(self, what: str) -> bool:
        """True if sensor ``what`` (one of :data:`STATUS_NAMES`) gave a valid reading."""
        try:
            return int(self.status[STATUS_NAMES.index(what)]) == STATUS_OK
        except ValueError:
            raise HalError(f'"{what}" is not a sensor: expected one of {list(STATUS_NAMES)}') from None

    @property
    def all_ok(self) -> bool:
        return not np.any(self.status)

    def wrench(self, sensor: str) -> np.ndarray:
        """Wrench ``[fx, fy, fz, tx, ty, tz]`` of F/T sensor ``sensor`` in its own frame."""
        return self.wrenches[FT_SENSOR_NAMES.index(sensor)] if sensor in FT_SENSOR_NAMES else _bad_sensor(sensor)


def _bad_sensor(sensor: str):
    raise HalError(f'"{sensor}" is not an F/T sensor: expected one of {list(FT_SENSOR_NAMES)}')
