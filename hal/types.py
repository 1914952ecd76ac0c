"""Data that crosses the hardware abstraction layer.

:class:`RobotInfo` and :class:`SensorFrame` hold what a real HRP-2 gives: encoder angles, a chest IMU
and four 6-axis F/T sensors, stamped with robot time. :class:`GroundTruth` is the simulator's truth,
for evaluation only: it travels on its own channel and the controller never reads it.

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

from servotau.description import FT_SENSOR_FRAMES, FT_SENSOR_NAMES, ROOT_JOINT
from servotau.errors import HalError

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
    ft_sensor_frames: tuple[str, ...] = FT_SENSOR_FRAMES  # model frame of each F/T sensor, ft_sensor_names order
    root_joint: str = ROOT_JOINT  # the model's free-flyer joint (the floating base)
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
        object.__setattr__(self, "ft_sensor_names", tuple(self.ft_sensor_names))
        object.__setattr__(self, "ft_sensor_frames", tuple(self.ft_sensor_frames))
        if len(self.ft_sensor_frames) != len(self.ft_sensor_names):
            raise HalError(f"RobotInfo.ft_sensor_frames = {list(self.ft_sensor_frames)}: expected one model frame "
                           f"per F/T sensor {list(self.ft_sensor_names)}")
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

    def ft_frame(self, sensor: str) -> str:
        """Model frame of F/T sensor ``sensor`` (where its wrench is expressed)."""
        return self.ft_sensor_frames[self.ft_index(sensor)]


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


@dataclass(frozen=True)
class GroundTruth:
    """What actually happened in the simulator at one tick (joint arrays in RobotInfo order).

    Simulation only, for evaluation and tests: it travels on its own channel (Drake's hardware_sim
    pattern), so that a real backend, which has no ground truth, runs the same controller stack.
    """

    time: float  # [s] sim time
    seq: int  # tick number, same as the SensorFrame's
    q: np.ndarray  # [rad] (n,) true joint angles (link side)
    dq: np.ndarray  # [rad/s] (n,) true joint velocities
    tau: np.ndarray  # [N m] (n,) joint torque transmitted to the link (motor through gear minus friction)
    current: np.ndarray  # [A] (n,) motor current after dead zone and saturation
    base_position: np.ndarray  # [m] (3,) waist position in world
    base_quat_wxyz: np.ndarray  # (4,) waist orientation in world, w first
    base_velocity: np.ndarray  # (6,) [m/s, rad/s] linear (world frame) then angular (waist frame)
    wrenches: np.ndarray  # [N, N m] (4, 6) noise-free, offset-free F/T readings (HAL convention)
    external_wrench: np.ndarray  # [N, N m] (6,) operator wrench, world frame, at the pushed body's CoM
    sole_contact_forces: np.ndarray  # [N] (2, 3) total contact force on the right and left sole, world frame

    FIELDS = ("q", "dq", "tau", "current", "base_position", "base_quat_wxyz", "base_velocity", "wrenches",
              "external_wrench", "sole_contact_forces")

    def to_vector(self) -> np.ndarray:
        """Flatten the arrays (FIELDS order) into one float64 vector (time and seq excluded)."""
        return np.concatenate([np.ravel(getattr(self, f)) for f in self.FIELDS])

    @classmethod
    def from_vector(cls, time: float, seq: int, vec: np.ndarray, n_joints: int) -> GroundTruth:
        """Inverse of :meth:`to_vector` for a robot with ``n_joints`` joints."""
        shapes = {"q": (n_joints,), "dq": (n_joints,), "tau": (n_joints,), "current": (n_joints,),
                  "base_position": (3,), "base_quat_wxyz": (4,), "base_velocity": (6,), "wrenches": (4, 6),
                  "external_wrench": (6,), "sole_contact_forces": (2, 3)}
        out, i = {}, 0
        for f in cls.FIELDS:
            size = int(np.prod(shapes[f]))
            out[f] = np.asarray(vec[i : i + size]).reshape(shapes[f])
            i += size
        return cls(time=time, seq=seq, **out)
