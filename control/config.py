"""Settings of the torque controller, read from ``config/control.toml`` and validated at construction.

Errors name the file, the field and the expected value (:class:`~servotau.errors.ConfigError`, a
``ValueError``); the dataclasses built directly raise :class:`~servotau.errors.ControlError` the same way.
The file format is documented in ``config/control.toml`` and ``docs/control.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from servotau.actuator import MotorModel, MotorParameters, checked_online_model, effect_names
from servotau.config import CONFIG_DIR, Section, load_toml, resolve_config_path
from servotau.errors import ConfigError, ControlError, IdentificationError
from servotau.hal.types import FT_SENSOR_NAMES, RobotInfo

from .gains import kd_from_k7, ks_from_k6

DEFAULT_PATH: Path = CONFIG_DIR / "control.toml"
"""The controller's default config file."""

FORMAT_VERSION = 1
BASES = ("fixed", "floating")
"""``fixed``: base locked (the paper's hanging robot); ``floating``: base state from the estimator."""

VELOCITY_FEEDFORWARDS = ("estimate", "reference", "reference_signs")
"""Velocity read by the motor-model feedforward (eq. 10): ``estimate`` dq_hat (the paper), ``reference`` dq_d,
``reference_signs`` dq_hat in the viscous term ``K_v dq`` and dq_d in the terms that switch with the direction of
motion (Coulomb ``k_c``, the extra effect terms)."""

AXES = ("fx", "fy", "fz", "tx", "ty", "tz")
"""Wrench axes, in the order of HAL wrenches ``[fx, fy, fz, tx, ty, tz]``."""


def _finite(name: str, value: object, ok, expected: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.number) or not math.isfinite(value):
        raise ControlError(f"{name} = {value!r}: expected {expected}")
    if not ok(float(value)):
        raise ControlError(f"{name} = {value!r}: expected {expected}")
    return float(value)


@dataclass(frozen=True)
class JointGains:
    """Torque-control gains of one joint (paper eq. 11-12)."""

    k_p: float = 2.0  # [-] torque proportional gain (paper: 2)
    k_s: float = 0.0  # [N m/rad] position stiffness
    k_d: float = 0.0  # [N m s/rad] velocity damping
    k_i: float = 0.0  # [1/s] torque integral gain (paper: 0)
    integral_limit: float = 10.0  # [N m] anti-windup clamp of |k_i * integral(e_tau)|
    k_iq: float = 0.0  # [1/s] position-integral rate, 1 / integral time (not in the paper; position_integral.py)
    position_integral_limit: float = 0.001  # [rad] clamp of the position integral

    def __post_init__(self):
        units = {"k_p": "-", "k_s": "N m/rad", "k_d": "N m s/rad", "k_i": "1/s", "integral_limit": "N m",
                 "k_iq": "1/s", "position_integral_limit": "rad"}
        for name, unit in units.items():
            value = _finite(f"JointGains.{name}", getattr(self, name), lambda v: v >= 0,
                            f"a finite number >= 0 [{unit}]")
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class ForceTask:
    """Force regulation on a frame of the foot or hand (paper section 5.4): ``f* = f_d + K_f (f_d - f_hat)``.

    The wrench is measured by F/T sensor ``sensor`` (HAL name) and expressed at ``frame`` (a frame of the
    robot model on the same body), moved by ``offset`` [m] in that frame (e.g. to the sole). Only ``axes``
    are regulated; the other axes of that wrench enter the feedforward as measured.
    """

    sensor: str = "right_ankle"
    frame: str = "ft_right_ankle"
    axes: tuple[str, ...] = AXES
    k_f: tuple[float, ...] = (1.0,) * 6  # [-] per axis (paper: 1)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # [m] task point in ``frame``

    def __post_init__(self):
        if self.sensor not in FT_SENSOR_NAMES:
            raise ControlError(f"ForceTask.sensor = {self.sensor!r}: expected one of {list(FT_SENSOR_NAMES)}")
        axes = tuple(self.axes)
        if not axes or len(set(axes)) != len(axes) or any(a not in AXES for a in axes):
            raise ControlError(f"ForceTask.axes = {self.axes!r}: expected distinct names among {list(AXES)}")
        k_f = tuple(self.k_f)
        if len(k_f) != len(axes):
            raise ControlError(f"ForceTask.k_f = {self.k_f!r}: expected {len(axes)} values, one per axis {axes}")
        k_f = tuple(_finite("ForceTask.k_f", v, lambda v: v >= 0, "finite numbers >= 0 [-]") for v in k_f)
        offset = tuple(self.offset)
        if len(offset) != 3:
            raise ControlError(f"ForceTask.offset = {self.offset!r}: expected 3 numbers [m]")
        offset = tuple(_finite("ForceTask.offset", v, lambda v: True, "finite numbers [m]") for v in offset)
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "k_f", k_f)
        object.__setattr__(self, "offset", offset)

    @property
    def axis_index(self) -> np.ndarray:
        """Indices of :attr:`axes` in ``[fx, fy, fz, tx, ty, tz]``."""
        return np.array([AXES.index(a) for a in self.axes], dtype=int)


@dataclass(frozen=True)
class SafetyLimits:
    """Limits checked on every tick; vectors are per joint in RobotInfo order."""

    max_command_error: np.ndarray  # [rad] |q_des - q| (the robot cuts its servos at 0.1 rad)
    max_torque: np.ndarray  # [N m] |tau_hat|
    max_velocity: np.ndarray  # [rad/s] |dq_hat|
    joint_limit_margin: float = 0.02  # [rad] q must stay in [q_min + margin, q_max - margin]

    def __post_init__(self):
        n = None
        for name, unit in (("max_command_error", "rad"), ("max_torque", "N m"), ("max_velocity", "rad/s")):
            arr = np.array(getattr(self, name), dtype=float)
            n = arr.size if n is None else n
            if arr.ndim != 1 or arr.size != n or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                raise ControlError(f"SafetyLimits.{name} = {arr.tolist()}: expected {n} finite numbers > 0 [{unit}]")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "joint_limit_margin", _finite(
            "SafetyLimits.joint_limit_margin", self.joint_limit_margin, lambda v: v >= 0, "a finite number >= 0 [rad]"))

    @classmethod
    def uniform(cls, n: int, max_command_error: float = 0.05, max_torque: float = 300.0, max_velocity: float = 5.0,
                joint_limit_margin: float = 0.02) -> SafetyLimits:
        """The same limits for all ``n`` joints."""
        return cls(np.full(n, max_command_error), np.full(n, max_torque), np.full(n, max_velocity), joint_limit_margin)


@dataclass(frozen=True)
class ControlConfig:
    """Everything the controller needs besides the robot: gains, motor models, task, safety limits."""

    joint_names: tuple[str, ...]  # all joints, RobotInfo order
    gains: Mapping[str, JointGains]  # torque-controlled joints (the others stay position-controlled)
    motors: Mapping[str, MotorModel]  # identified actuator model of each torque-controlled joint
    safety: SafetyLimits
    base: str = "fixed"
    contacts: tuple[str, ...] = ()  # F/T sensors whose measured wrench enters the feedforward (-J^T f_hat)
    force: ForceTask | None = None
    sign_velocity: float = 0.01  # [rad/s] Coulomb sign smoothing: k_c tanh(dq / sign_velocity)
    fade_time: float = 0.5  # [s] the bumpless-switch offset fades to zero over this time
    velocity_feedforward: str = "estimate"  # velocity of the motor-model feedforward (VELOCITY_FEEDFORWARDS)
    rest_velocity: float = 0.001  # [rad/s] the position integral runs on a joint while |dq_d| < rest_velocity
    source: str = "<direct>"  # file the config came from
    _torque_mask: np.ndarray = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        names = tuple(self.joint_names)
        object.__setattr__(self, "joint_names", names)
        # MotorParameters.__getitem__ raises IdentificationError, not KeyError, so `in` fails on it: use its dict.
        object.__setattr__(self, "motors", dict(getattr(self.motors, "models", self.motors)))
        for j in self.gains:
            if j not in names:
                raise ControlError(f'gains: joint "{j}" is not a robot joint: expected one of {list(names)}')
            if not isinstance(self.gains[j], JointGains):
                raise ControlError(f'gains["{j}"] = {self.gains[j]!r}: expected a JointGains')
            if j not in self.motors:
                raise ControlError(f'joint "{j}" is torque-controlled but has no motor model: expected one of '
                                   f"{sorted(self.motors)}")
            if not isinstance(self.motors[j], MotorModel):
                raise ControlError(f'motors["{j}"] = {self.motors[j]!r}: expected a MotorModel')
        gains = {j: self.gains[j] for j in names if j in self.gains}  # RobotInfo order
        object.__setattr__(self, "gains", MappingProxyType(gains))
        object.__setattr__(self, "motors", MappingProxyType({j: self.motors[j] for j in gains}))
        if not isinstance(self.safety, SafetyLimits) or self.safety.max_torque.size != len(names):
            raise ControlError(f"safety = {self.safety!r}: expected SafetyLimits for {len(names)} joints")
        if self.base not in BASES:
            raise ControlError(f"base = {self.base!r}: expected one of {list(BASES)}")
        if self.velocity_feedforward not in VELOCITY_FEEDFORWARDS:
            raise ControlError(f"velocity_feedforward = {self.velocity_feedforward!r}: expected one of "
                               f"{list(VELOCITY_FEEDFORWARDS)}")
        contacts = tuple(self.contacts)
        for c in contacts:
            if c not in FT_SENSOR_NAMES:
                raise ControlError(f"contacts: {c!r} is not an F/T sensor: expected one of {list(FT_SENSOR_NAMES)}")
        if len(set(contacts)) != len(contacts):
            raise ControlError(f"contacts = {list(contacts)}: expected distinct sensors")
        object.__setattr__(self, "contacts", contacts)
        if self.force is not None and not isinstance(self.force, ForceTask):
            raise ControlError(f"force = {self.force!r}: expected a ForceTask or None")
        object.__setattr__(self, "sign_velocity", _finite("sign_velocity", self.sign_velocity, lambda v: v > 0,
                                                          "a finite number > 0 [rad/s]"))
        object.__setattr__(self, "fade_time", _finite("fade_time", self.fade_time, lambda v: v >= 0,
                                                      "a finite number >= 0 [s]"))
        object.__setattr__(self, "rest_velocity", _finite("rest_velocity", self.rest_velocity, lambda v: v > 0,
                                                          "a finite number > 0 [rad/s]"))
        mask = np.array([j in gains for j in names])
        mask.setflags(write=False)
        object.__setattr__(self, "_torque_mask", mask)

    @property
    def torque_joints(self) -> tuple[str, ...]:
        """The torque-controlled joints, RobotInfo order."""
        return tuple(self.gains)

    @property
    def torque_mask(self) -> np.ndarray:
        """(n,) bool, True for torque-controlled joints."""
        return self._torque_mask

    def joint_vector(self, attr: str) -> np.ndarray:
        """(n,) gain ``attr`` of :class:`JointGains` per joint, 0 for position-controlled joints."""
        return np.array([getattr(self.gains[j], attr) if j in self.gains else 0.0 for j in self.joint_names])

    def motor_vector(self, attr: str) -> np.ndarray:
        """(n,) motor parameter ``attr`` (k_tau, k_v, k_c) per joint, 0 for position-controlled joints."""
        return np.array([(getattr(self.motors[j], attr) or 0.0) if j in self.motors else 0.0
                         for j in self.joint_names])

    # -- files -----------------------------------------------------------------------------------
    @classmethod
    def from_toml(cls, path: str | Path, info: RobotInfo) -> ControlConfig:
        """Read ``path`` (resolved against ``config/``) for the robot ``info``.

        Raises:
            ConfigError: Naming the file, the field and the expected value.
        """
        return cls.from_section(load_toml(path), info)

    @classmethod
    def from_mapping(cls, data: Mapping, info: RobotInfo, file: str = "<mapping>") -> ControlConfig:
        """Same as :meth:`from_toml` for an already parsed table (paths resolved against ``config/``)."""
        return cls.from_section(Section(data, file, ""), info)

    @classmethod
    def from_section(cls, root: Section, info: RobotInfo) -> ControlConfig:
        root.check_keys(["version", "motors", "base", "contacts", "sign_velocity", "fade_time", "velocity_feedforward",
                         "rest_velocity", "torque_joints", "defaults", "joints", "force", "safety"])
        version = root.int("version")
        if version != FORMAT_VERSION:
            raise root.error("version", version, f"{FORMAT_VERSION}")
        motors_path = root.str("motors")
        try:
            motors_file = resolve_config_path(motors_path)
            motors = dict(MotorParameters.load_toml(motors_file).models)
        except ConfigError as err:
            raise ConfigError(f"{root.file}: field 'motors' = {motors_path!r}: {err}") from err
        _check_extra_terms(motors, motors_file, info.period)
        names = info.joint_names

        torque_joints = root.data.get("torque_joints", [])
        if not isinstance(torque_joints, list) or not all(isinstance(j, str) for j in torque_joints):
            raise root.error("torque_joints", torque_joints, "a list of joint names")
        for j in torque_joints:
            if j not in names:
                raise root.error("torque_joints", j, f"joints of {info.name}, among {list(names)}")
            if j not in motors:
                raise root.error("torque_joints", j, f"joints with a motor model in {motors_path}: {list(motors)}")
        if len(set(torque_joints)) != len(torque_joints):
            raise root.error("torque_joints", torque_joints, "distinct joint names")

        defaults = root.section("defaults", {})
        gain_keys = ["k_p", "k_i", "integral_limit", "k_iq", "position_integral_limit", "k6", "k_s", "k7", "k_d",
                     "k7_scaling"]
        defaults.check_keys(gain_keys)
        joints = root.section("joints", {})
        for j in joints.keys():
            if j not in torque_joints:
                raise joints.error(j, joints.data[j], f"a table for a joint listed in torque_joints {torque_joints}")
        gains = {}
        for j in torque_joints:
            own = joints.section(j, {})
            own.check_keys(gain_keys)
            gains[j] = _joint_gains(own, defaults, motors[j].k_tau)

        force = None
        if "force" in root:
            fs = root.section("force")
            fs.check_keys(["sensor", "frame", "axes", "k_f", "offset"])
            axes = fs.data.get("axes", list(AXES))
            if (not isinstance(axes, list) or not axes or len(set(axes)) != len(axes)
                    or any(a not in AXES for a in axes)):
                raise fs.error("axes", axes, f"a list of distinct axes among {list(AXES)}")
            k_f = fs.floats("k_f", len(axes), unit="-")
            if any(v < 0 for v in k_f):
                raise fs.error("k_f", k_f, f"a list of {len(axes)} finite numbers >= 0 [-]")
            force = ForceTask(
                sensor=fs.str("sensor", choices=FT_SENSOR_NAMES),
                frame=fs.str("frame"),
                axes=tuple(axes),
                k_f=tuple(k_f),
                offset=tuple(fs.floats("offset", 3, [0.0, 0.0, 0.0], unit="m")),
            )

        contacts = root.data.get("contacts", [])
        if (not isinstance(contacts, list) or len(set(map(str, contacts))) != len(contacts)
                or any(c not in FT_SENSOR_NAMES for c in contacts)):
            raise root.error("contacts", contacts, f"a list of distinct F/T sensors among {list(FT_SENSOR_NAMES)}")

        return cls(
            joint_names=names,
            gains=gains,
            motors={j: motors[j] for j in torque_joints},
            safety=_safety(root.section("safety", {}), info),
            base=root.str("base", "fixed", choices=BASES),
            contacts=tuple(contacts),
            force=force,
            sign_velocity=root.float("sign_velocity", 0.01, min=0.0, strict_min=True, unit="rad/s"),
            fade_time=root.float("fade_time", 0.5, min=0.0, unit="s"),
            velocity_feedforward=root.str("velocity_feedforward", "estimate", choices=VELOCITY_FEEDFORWARDS),
            rest_velocity=root.float("rest_velocity", 0.001, min=0.0, strict_min=True, unit="rad/s"),
            source=root.file,
        )


def _check_extra_terms(motors: Mapping[str, MotorModel], file: Path, period: float) -> None:
    """Every extra term of the motor file must be one the controller's feedforward can evaluate on-line.

    Raises:
        ConfigError: Naming the motor file, the field ``joints.<joint>.extra.<term>`` and what was expected.
    """
    known = effect_names()
    for joint, m in motors.items():
        for name, term in m.extra.items():
            field_ = f"joints.{joint}.extra.{name}"
            if name not in known:
                raise ConfigError(f"{file}: field '{field_}': unknown motor-model term '{name}': expected one of "
                                  f"the model workbench's effects {known}")
            try:
                one = MotorModel(k_tau=m.k_tau, k_v=m.k_v, extra={name: term}, provenance=m.provenance)
                checked_online_model(one, period)
            except IdentificationError as err:
                raise ConfigError(f"{file}: field '{field_}' (shape {dict(term.shape)}): joint \"{joint}\": {err}: "
                                  f"expected the shape parameters of effect '{name}'") from err


K7_SCALINGS = ("constant", "inverse_sqrt_k6")
"""``k7_scaling``: ``constant`` uses k7 (k_d) as given; ``inverse_sqrt_k6`` divides it by sqrt(K6), so the given
k7 is the value at K6 = 1 and lower stiffnesses get more velocity feedback (docs/control.md: the measured
stability window of k7 moves up as K6 falls)."""


def _joint_gains(own: Section, defaults: Section, k_tau: float) -> JointGains:
    """Gains of one joint: its own table first, then [defaults]; k6/k7 are converted to k_s/k_d, and k_d is
    divided by sqrt(K6) with ``k7_scaling = "inverse_sqrt_k6"``."""

    def pick(key: str) -> Section | None:
        return own if key in own else defaults if key in defaults else None

    def value(key: str, default: float, unit: str) -> float:
        sec = pick(key)
        return default if sec is None else sec.float(key, min=0.0, unit=unit)

    k_p = value("k_p", 2.0, "-")
    for sec in (own, defaults):
        for a, b in (("k6", "k_s"), ("k7", "k_d")):
            if a in sec and b in sec:
                raise sec.error(b, sec.data[b], f"either {a} or {b}, not both")

    def stiffness(native: str, si: str, unit: str, convert) -> float:
        # The joint's own table wins over [defaults], whichever of the two forms each uses.
        for sec in (own, defaults):
            if native in sec:
                return float(convert(k_tau, k_p, sec.float(native, min=0.0, unit=unit_native[native]))[0])
            if si in sec:
                return sec.float(si, min=0.0, unit=unit)
        return 0.0

    unit_native = {"k6": "-, 1 = the native servo", "k7": "s"}
    k_s = stiffness("k6", "k_s", "N m/rad", ks_from_k6)
    k_d = stiffness("k7", "k_d", "N m s/rad", kd_from_k7)
    sec = pick("k7_scaling")
    scaling = "constant" if sec is None else sec.str("k7_scaling", choices=K7_SCALINGS)
    if scaling == "inverse_sqrt_k6":
        k6 = k_tau * (1.0 + k_p) * k_s
        if not k6 > 0:
            raise sec.error("k7_scaling", scaling, "'constant' for a joint without position gain (k6 = 0)")
        k_d /= math.sqrt(k6)
    return JointGains(
        k_p=k_p,
        k_s=k_s,
        k_d=k_d,
        k_i=value("k_i", 0.0, "1/s"),
        integral_limit=value("integral_limit", 10.0, "N m"),
        k_iq=value("k_iq", 0.0, "1/s"),
        position_integral_limit=value("position_integral_limit", 0.001, "rad"),
    )


def _safety(sec: Section, info: RobotInfo) -> SafetyLimits:
    keys = {"max_command_error": ("rad", 0.05), "max_torque": ("N m", 300.0), "max_velocity": ("rad/s", 5.0)}
    sec.check_keys([*keys, "joint_limit_margin", "joints"])
    n = info.nq
    arrays = {k: np.full(n, sec.float(k, d, min=0.0, strict_min=True, unit=u)) for k, (u, d) in keys.items()}
    per_joint = sec.section("joints", {})
    for j in per_joint.keys():
        if j not in info.joint_names:
            raise per_joint.error(j, per_joint.data[j], f"a table named after a joint of {info.name}, "
                                                        f"among {list(info.joint_names)}")
        js = per_joint.section(j)
        js.check_keys(list(keys))
        for k, (u, _) in keys.items():
            if k in js:
                arrays[k][info.joint_index(j)] = js.float(k, min=0.0, strict_min=True, unit=u)
    return SafetyLimits(**arrays, joint_limit_margin=sec.float("joint_limit_margin", 0.02, min=0.0, unit="rad"))
