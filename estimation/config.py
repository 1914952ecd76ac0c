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
from servotau.config import CONFIG_DIR, Section, load_toml, resolve_config_path
from servotau.errors import ConfigError, EstimationError, IdentificationError
from servotau.hal.types import FT_SENSOR_NAMES

DEFAULT_PATH: Path = CONFIG_DIR / "estimation.toml"
"""The estimator's default config file."""

EVAL_AT = ("centre", "last")
ANGULAR_ACCELERATION = ("savgol", "neglect")


@dataclass(frozen=True)
class FilterSettings:
    """Savitzky-Golay window [samples] and polynomial order of one sensor group."""

    window: int
    order: int

    def __post_init__(self):
        for name in ("window", "order"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise EstimationError(f"FilterSettings.{name}={value!r}: expected an integer")
        if self.order < 0 or self.window < self.order + 2:
            raise EstimationError(
                f"FilterSettings(window={self.window}, order={self.order}): expected order >= 0 and "
                "window >= order + 2 (a least-squares fit, not an interpolation)"
            )


@dataclass(frozen=True)
class ModelPerturbation:
    """Random errors of the estimator's inertial parameters, for robustness studies.

    Each body (joint bodies and welded bodies) gets its mass and rotational inertia scaled by
    ``1 + mass_scale_std * N(0, 1)`` (clipped to [0.5, 1.5]) and its CoM moved by
    ``com_offset_std * N(0, I3)`` [m], from ``numpy.random.default_rng(seed)``.
    """

    mass_scale_std: float = 0.0  # [-]
    com_offset_std: float = 0.0  # [m]
    seed: int = 0

    def __post_init__(self):
        for name in ("mass_scale_std", "com_offset_std"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and 0.0 <= value <= 0.5):
                raise EstimationError(f"ModelPerturbation.{name}={value!r}: expected a number in [0, 0.5]")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise EstimationError(f"ModelPerturbation.seed={self.seed!r}: expected an integer >= 0")

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
    velocity_window: int = 20  # [samples] zero-delay velocity filter ("last", order 2)

    def __post_init__(self):
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
        if isinstance(self.velocity_window, bool) or not isinstance(self.velocity_window, int) or \
                self.velocity_window < 4:
            raise EstimationError(f"PredictionSettings.velocity_window={self.velocity_window!r}: expected an int >= 4")
        object.__setattr__(self, "k_tau", MappingProxyType(dict(self.k_tau)))
        object.__setattr__(self, "k_v", MappingProxyType(dict(self.k_v)))

    @property
    def enabled(self) -> bool:
        return bool(self.k_tau)

    @classmethod
    def from_motors(cls, motors: Mapping[str, MotorModel], velocity_window: int = 20) -> PredictionSettings:
        """``k_tau`` and ``k_v`` of the motor models ``motors`` (by joint name; e.g. a ``MotorParameters``)."""
        return cls(k_tau={j: m.k_tau for j, m in motors.items()}, k_v={j: m.k_v for j, m in motors.items()},
                   velocity_window=velocity_window)


def _prediction(pred: Section) -> PredictionSettings:
    """``[prediction]``: ``motors`` (a motor file of config/motors/, optional: no prediction without it),
    ``joints`` (those of the file it predicts; default all) and ``velocity_window``."""
    pred.check_keys(["motors", "joints", "velocity_window"])
    velocity_window = pred.int("velocity_window", 20, min=4)
    if "motors" not in pred:
        if "joints" in pred:
            raise pred.error("joints", pred.data["joints"], "no joints without a motor file (field 'motors')")
        return PredictionSettings(velocity_window=velocity_window)
    path = pred.str("motors")
    try:
        motors = MotorParameters.load_toml(resolve_config_path(path))
    except (ConfigError, IdentificationError) as err:
        raise ConfigError(f"{pred.file}: field 'prediction.motors' = {path!r}: {err}") from err
    joints = pred.data.get("joints", list(motors))
    if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
        raise pred.error("joints", joints, "a list of joint names")
    if any(j not in motors for j in joints):
        raise pred.error("joints", joints, f"joints with a motor model in {path}: {list(motors)}")
    return PredictionSettings.from_motors({j: motors[j] for j in joints}, velocity_window)


@dataclass(frozen=True, eq=False)
class EstimatorConfig:
    """Everything that defines a :class:`~servotau.estimation.TorqueEstimator` (compared by identity:
    it holds arrays)."""

    encoders: FilterSettings = FilterSettings(80, 2)  # q, dq, ddq
    imu: FilterSettings = FilterSettings(80, 1)  # gyro (and its derivative), accelerometer
    ft: FilterSettings = FilterSettings(80, 1)  # F/T wrenches (value only)
    eval_at: str = "centre"  # "centre": every output delayed (N-1)/2; "last": values not delayed
    align: bool = True  # delay the inputs of shorter windows so that all outputs share one time stamp
    angular_acceleration: str = "savgol"  # base angular acceleration: SG derivative of the gyro, or 0
    imu_frame: str = "imu"  # model frame of the IMU
    unknown_wrench_link: str = "CHEST_LINK1"  # body that takes the unknown external wrench (paper: torso)
    armature: bool = True  # rotor inertias (MJCF armature) in the RNEA, as in the simulated joint torque
    ft_offsets: np.ndarray = field(default_factory=lambda: np.zeros((len(FT_SENSOR_NAMES), 6)))  # [N, N m]
    gyro_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))  # [rad/s] IMU frame
    perturbation: ModelPerturbation = ModelPerturbation()
    prediction: PredictionSettings = PredictionSettings()

    def __post_init__(self):
        for name in ("encoders", "imu", "ft"):
            if not isinstance(getattr(self, name), FilterSettings):
                raise EstimationError(f"EstimatorConfig.{name}: expected a FilterSettings")
        if self.eval_at not in EVAL_AT:
            raise EstimationError(f"EstimatorConfig.eval_at={self.eval_at!r}: expected one of {EVAL_AT}")
        if self.angular_acceleration not in ANGULAR_ACCELERATION:
            raise EstimationError(
                f"EstimatorConfig.angular_acceleration={self.angular_acceleration!r}: expected one of "
                f"{ANGULAR_ACCELERATION}"
            )
        if self.angular_acceleration == "savgol" and self.imu.order < 1:
            raise EstimationError("EstimatorConfig: angular_acceleration='savgol' needs imu.order >= 1")
        if self.encoders.order < 2:
            raise EstimationError(f"EstimatorConfig.encoders.order={self.encoders.order}: expected >= 2 (ddq)")
        for name, shape in (("ft_offsets", (len(FT_SENSOR_NAMES), 6)), ("gyro_bias", (3,))):
            arr = np.array(getattr(self, name), dtype=float)
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise EstimationError(f"EstimatorConfig.{name} has shape {arr.shape}: expected finite {shape}")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    # -- variants ------------------------------------------------------------------------------
    def with_window(self, window: int) -> EstimatorConfig:
        """The same config with every filter window set to ``window`` [samples]."""
        return replace(
            self,
            encoders=FilterSettings(window, self.encoders.order),
            imu=FilterSettings(window, self.imu.order),
            ft=FilterSettings(window, self.ft.order),
        )

    def low_delay(self, window: int | None = None, encoders_order: int = 3, imu_order: int = 2,
                  ft_order: int = 1) -> EstimatorConfig:
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
        root.check_keys(["eval_at", "align", "angular_acceleration", "imu_frame", "unknown_wrench_link",
                         "armature", "filters", "calibration", "model", "prediction", "low_delay"])
        defaults = cls()
        filters = root.section("filters", {})
        filters.check_keys(["encoders", "imu", "ft"])

        def filt(name: str) -> FilterSettings:
            base = getattr(defaults, name)
            sec = filters.section(name, {})
            sec.check_keys(["window", "order"])
            window, order = sec.int("window", base.window, min=2), sec.int("order", base.order, min=0)
            if window < order + 2:
                raise sec.error("window", window, f"an integer >= order + 2 = {order + 2}")
            return FilterSettings(window, order)

        cal = root.section("calibration", {})
        cal.check_keys(["gyro_bias", "ft_offsets"])
        offsets_sec = cal.section("ft_offsets", {})
        offsets_sec.check_keys(FT_SENSOR_NAMES)
        offsets = np.array([offsets_sec.floats(s, 6, [0.0] * 6, unit="N, N m") for s in FT_SENSOR_NAMES])

        mod = root.section("model", {})
        mod.check_keys(["mass_scale_std", "com_offset_std", "seed"])
        config = cls(
            encoders=filt("encoders"),
            imu=filt("imu"),
            ft=filt("ft"),
            eval_at=root.str("eval_at", defaults.eval_at, choices=EVAL_AT),
            align=root.bool("align", defaults.align),
            angular_acceleration=root.str("angular_acceleration", defaults.angular_acceleration,
                                          choices=ANGULAR_ACCELERATION),
            imu_frame=root.str("imu_frame", defaults.imu_frame),
            unknown_wrench_link=root.str("unknown_wrench_link", defaults.unknown_wrench_link),
            armature=root.bool("armature", defaults.armature),
            ft_offsets=offsets,
            gyro_bias=np.array(cal.floats("gyro_bias", 3, [0.0] * 3, unit="rad/s")),
            perturbation=ModelPerturbation(
                mass_scale_std=mod.float("mass_scale_std", 0.0, min=0.0, max=0.5),
                com_offset_std=mod.float("com_offset_std", 0.0, min=0.0, max=0.5, unit="m"),
                seed=mod.int("seed", 0, min=0),
            ),
            prediction=_prediction(root.section("prediction", {})),
        )
        if variant == "centred":
            return config
        if variant != "low_delay":
            raise EstimationError(f"variant={variant!r}: expected 'centred' or 'low_delay'")
        low = root.section("low_delay", {})
        low.check_keys(["window", "encoders_order", "imu_order", "ft_order"])
        return config.low_delay(
            window=low.int("window", config.encoders.window, min=4),
            encoders_order=low.int("encoders_order", 3, min=2),
            imu_order=low.int("imu_order", 2, min=1),
            ft_order=low.int("ft_order", 1, min=0),
        )

