"""Settings of the joint-torque estimator, read from ``config/estimation.toml``.

Every field has the paper's value as default (section 5.1: 80-sample windows at 1 kHz, order 2
for the encoders, order 1 for the IMU and the F/T sensors, evaluated at the window centre).
Validation happens at construction: a bad value raises :class:`~servotau.errors.EstimationError`
(direct construction) or :class:`~servotau.errors.ConfigError` naming the file and field (TOML).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType

import numpy as np

from servotau.actuator import MotorModel, MotorParameters
from servotau.config import CONFIG_DIR, Section, check_settings, load_dataclass, load_toml, resolve_config_path, setting
from servotau.errors import ConfigError, EstimationError, IdentificationError
from servotau.hal.types import FT_SENSOR_NAMES

DEFAULT_PATH: Path = CONFIG_DIR / "estimation.toml"
"""The estimator's default config file."""

EVAL_AT = ("centre", "last")
ANGULAR_ACCELERATION = ("savgol", "neglect")


@dataclass(frozen=True)
class FilterSettings:
    """Savitzky-Golay window [samples] and polynomial order of one sensor group (window >= order + 2: a
    least-squares fit, not an interpolation)."""

    window: int = setting(min="order + 2")
    order: int = setting(min=0)

    def __post_init__(self):
        check_settings(self, EstimationError)


@dataclass(frozen=True)
class ModelPerturbation:
    """Random errors of the estimator's inertial parameters, for robustness studies.

    Each body (joint bodies and welded bodies) gets its mass and rotational inertia scaled by
    ``1 + mass_scale_std * N(0, 1)`` (clipped to [0.5, 1.5]) and its CoM moved by
    ``com_offset_std * N(0, I3)`` [m], from ``numpy.random.default_rng(seed)``.
    """

    mass_scale_std: float = setting(0.0, min=0, max=0.5)  # [-]
    com_offset_std: float = setting(0.0, unit="m", min=0, max=0.5)
    seed: int = setting(0, min=0)

    def __post_init__(self):
        check_settings(self, EstimationError)

    @property
    def enabled(self) -> bool:
        return self.mass_scale_std > 0.0 or self.com_offset_std > 0.0


@dataclass(frozen=True)
class PredictionSettings:
    """Optional model-based prediction of the torque to the frame time (beyond the paper).

    The paper's actuator model (eq. 6 without Coulomb term), ``q_des - q = k_tau tau + k_v dq``,
    gives a zero-delay torque ``m = (q_des - q - k_v dq) / k_tau`` for the joints listed here; the
    estimator corrects it with its own delayed estimate (see :mod:`.prediction`). In the TOML file the
    joints' ``k_tau`` and ``k_v`` come from a motor file (``[prediction] motors``, :meth:`from_motors`).
    """

    k_tau: Mapping[str, float] = field(default_factory=dict)  # [rad/(N m)] per joint name
    k_v: Mapping[str, float] = field(default_factory=dict)  # [rad/(rad/s)] per joint name
    velocity_window: int = setting(20, unit="samples", min=4)  # zero-delay velocity filter ("last", order 2)

    def __post_init__(self):
        check_settings(self, EstimationError)
        if set(self.k_tau) != set(self.k_v):
            raise EstimationError(
                f"PredictionSettings: k_tau and k_v must name the same joints, got {sorted(self.k_tau)} "
                f"and {sorted(self.k_v)}"
            )
        for name, table in (("k_tau", self.k_tau), ("k_v", self.k_v)):
            for joint, value in table.items():
                ok = isinstance(value, int | float) and math.isfinite(value)
                if not ok or (name == "k_tau" and value <= 0.0):
                    raise EstimationError(
                        f"PredictionSettings.{name}[{joint!r}]={value!r}: expected a finite number"
                        + (" > 0 [rad/(N m)]" if name == "k_tau" else " [rad s/rad]")
                    )
        object.__setattr__(self, "k_tau", MappingProxyType(dict(self.k_tau)))
        object.__setattr__(self, "k_v", MappingProxyType(dict(self.k_v)))

    @property
    def enabled(self) -> bool:
        return bool(self.k_tau)

    @classmethod
    def from_motors(cls, motors: Mapping[str, MotorModel], **settings) -> PredictionSettings:
        """``k_tau`` and ``k_v`` of the motor models ``motors`` (by joint name; e.g. a ``MotorParameters``);
        ``settings``: the other fields."""
        return cls(k_tau={j: m.k_tau for j, m in motors.items()}, k_v={j: m.k_v for j, m in motors.items()},
                   **settings)


def _prediction(pred: Section) -> PredictionSettings:
    """``[prediction]``: ``motors`` (a motor file of config/motors/, optional: no prediction without it),
    ``joints`` (those of the file it predicts; default all) and ``velocity_window``."""
    pred.check_keys(["motors", "joints", "velocity_window"])
    if "motors" not in pred:
        if "joints" in pred:
            raise pred.error("joints", pred.data["joints"], "no joints without a motor file (field 'motors')")
        return load_dataclass(PredictionSettings, pred)
    path = pred.str("motors")
    try:
        motors = MotorParameters.load_toml(resolve_config_path(path, pred.file))
    except (ConfigError, IdentificationError) as err:
        raise ConfigError(f"{pred.file}: field 'prediction.motors' = {path!r}: {err}") from err
    joints = pred.data.get("joints", list(motors))
    if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
        raise pred.error("joints", joints, "a list of joint names")
    if any(j not in motors for j in joints):
        raise pred.error("joints", joints, f"joints with a motor model in {path}: {list(motors)}")
    table = PredictionSettings.from_motors({j: motors.servo_model(j) for j in joints})  # k_tau, else an error
    return load_dataclass(PredictionSettings, pred, ignore=["motors", "joints"], k_tau=table.k_tau, k_v=table.k_v)


@dataclass(frozen=True)
class LowDelaySettings:
    """The ``[low_delay]`` table: the zero-delay variant of :meth:`EstimatorConfig.low_delay`."""

    window: int | None = setting(None, unit="samples", min=4)  # None: the encoders' window, for every filter
    encoders_order: int = setting(3, min=2)  # ddq is not the top derivative
    imu_order: int = setting(2, min=1)  # the gyro derivative is not the top derivative
    ft_order: int = setting(1, min=0)


@dataclass(frozen=True, eq=False)
class EstimatorConfig:
    """Everything that defines a :class:`~servotau.estimation.TorqueEstimator` (compared by identity:
    it holds arrays)."""

    encoders: FilterSettings = setting(FilterSettings(80, 2))  # q, dq, ddq
    imu: FilterSettings = setting(FilterSettings(80, 1))  # gyro (and its derivative), accelerometer
    ft: FilterSettings = setting(FilterSettings(80, 1))  # F/T wrenches (value only)
    eval_at: str = setting("centre", choices=EVAL_AT)  # "centre": every output delayed (N-1)/2; "last": not delayed
    align: bool = setting(True)  # delay the inputs of shorter windows so that all outputs share one time stamp
    angular_acceleration: str = setting("savgol", choices=ANGULAR_ACCELERATION)  # SG derivative of the gyro, or 0
    imu_frame: str = setting("imu")  # model frame of the IMU
    unknown_wrench_link: str = setting("CHEST_LINK1")  # body that takes the unknown external wrench (paper: torso)
    armature: bool = setting(True)  # rotor inertias (MJCF armature) in the RNEA, as in the simulated joint torque
    ft_offsets: np.ndarray = setting(unit="N, N m", shape=(len(FT_SENSOR_NAMES), 6),
                                     factory=lambda: np.zeros((len(FT_SENSOR_NAMES), 6)))  # per F/T sensor
    gyro_bias: np.ndarray = setting(unit="rad/s", shape=(3,), factory=lambda: np.zeros(3))  # IMU frame
    perturbation: ModelPerturbation = setting(ModelPerturbation())
    prediction: PredictionSettings = setting(PredictionSettings())
    # [s] of robot time: skipped frames are filled by linear interpolation between the readings either side
    # (the filters stay on the robot's time grid); a gap up to this long keeps the estimate valid, a longer
    # one makes it invalid (finite, flagged by ``Estimate.gap_flush``) until a window of real readings follows
    max_gap: float = setting(0.02, unit="s", min=0)

    def __post_init__(self):
        check_settings(self, EstimationError)
        if self.angular_acceleration == "savgol" and self.imu.order < 1:
            raise EstimationError("EstimatorConfig: angular_acceleration='savgol' needs imu.order >= 1")
        if self.encoders.order < 2:
            raise EstimationError(f"EstimatorConfig.encoders.order={self.encoders.order}: expected >= 2 (ddq)")
        for name in ("ft_offsets", "gyro_bias"):
            getattr(self, name).setflags(write=False)

    # -- variants ------------------------------------------------------------------------------
    def with_window(self, window: int) -> EstimatorConfig:
        """The same config with every filter window set to ``window`` [samples]."""
        return replace(
            self,
            encoders=FilterSettings(window, self.encoders.order),
            imu=FilterSettings(window, self.imu.order),
            ft=FilterSettings(window, self.ft.order),
        )

    def low_delay(self, window: int | None = None, encoders_order: int = LowDelaySettings.encoders_order,
                  imu_order: int = LowDelaySettings.imu_order, ft_order: int = LowDelaySettings.ft_order
                  ) -> EstimatorConfig:
        """The zero-delay variant: polynomials evaluated at the newest sample, one order more than the
        highest derivative used, so that no output is the (delayed) top derivative of its fit.

        Args:
            window: Window of every filter [samples]; None keeps the current ones.
            encoders_order: Order of the encoder fit (3: ddq is not the top derivative).
            imu_order: Order of the IMU fit (2: the gyro derivative is not the top derivative).
            ft_order: Order of the F/T fit.
        """
        enc, imu, ft = (window or self.encoders.window), (window or self.imu.window), (window or self.ft.window)
        return replace(
            self,
            eval_at="last",
            encoders=FilterSettings(enc, encoders_order),
            imu=FilterSettings(imu, imu_order),
            ft=FilterSettings(ft, ft_order),
        )

    def with_calibration(self, ft_offsets: np.ndarray | None = None,
                         gyro_bias: np.ndarray | None = None) -> EstimatorConfig:
        """The same config with calibrated F/T offsets (4, 6) [N, N m] and/or gyro bias (3,) [rad/s]."""
        return replace(
            self,
            ft_offsets=self.ft_offsets if ft_offsets is None else ft_offsets,
            gyro_bias=self.gyro_bias if gyro_bias is None else gyro_bias,
        )

    # -- TOML ----------------------------------------------------------------------------------
    @classmethod
    def from_toml(cls, path: str | Path = DEFAULT_PATH, variant: str = "centred") -> EstimatorConfig:
        """Read ``path`` (see config/estimation.toml): ``variant="centred"`` as written (outputs delayed by
        half a window, as in the paper); ``"low_delay"`` applies its [low_delay] table."""
        root = load_toml(path)
        defaults = cls()
        filters = root.section("filters", {})
        filters.check_keys(["encoders", "imu", "ft"])
        windows = {name: load_dataclass(FilterSettings, filters.section(name, {}), base=getattr(defaults, name))
                   for name in ("encoders", "imu", "ft")}
        cal = root.section("calibration", {})
        cal.check_keys(["gyro_bias", "ft_offsets"])
        offsets_sec = cal.section("ft_offsets", {})
        offsets_sec.check_keys(FT_SENSOR_NAMES)
        offsets = defaults.ft_offsets.copy()
        for i, s in enumerate(FT_SENSOR_NAMES):
            if s in offsets_sec:
                offsets[i] = offsets_sec.floats(s, 6, unit="N, N m")
        gyro_bias = np.array(cal.floats("gyro_bias", 3, unit="rad/s")) if "gyro_bias" in cal else defaults.gyro_bias
        config = load_dataclass(
            cls, root, ignore=["filters", "calibration", "model", "prediction", "low_delay"], **windows,
            ft_offsets=offsets, gyro_bias=gyro_bias,
            perturbation=load_dataclass(ModelPerturbation, root.section("model", {})),
            prediction=_prediction(root.section("prediction", {})),
        )
        if variant == "centred":
            return config
        if variant != "low_delay":
            raise EstimationError(f"variant={variant!r}: expected 'centred' or 'low_delay'")
        low = load_dataclass(LowDelaySettings, root.section("low_delay", {}))
        return config.low_delay(window=low.window or config.encoders.window, encoders_order=low.encoders_order,
                                imu_order=low.imu_order, ft_order=low.ft_order)
