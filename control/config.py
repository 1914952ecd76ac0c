"""Settings of the torque controller, read from ``config/control.toml`` and validated at construction.

Errors name the file, the field and the expected value (:class:`~servotau.errors.ConfigError`, a
``ValueError``); the dataclasses built directly raise :class:`~servotau.errors.ControlError` the same way.
The file format is documented in ``config/control.toml`` and ``docs/control.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from types import MappingProxyType

import numpy as np

from servotau.actuator import MotorModel, MotorParameters, checked_online_model, effect_names
from servotau.config import CONFIG_DIR, Section, check_settings, load_dataclass, load_toml, resolve_config_path, setting
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


@dataclass(frozen=True)
class JointGains:
    """Torque-control gains of one joint (paper eq. 11-12)."""

    k_p: float = setting(2.0, unit="-", min=0)  # torque proportional gain (paper: 2)
    k_s: float = setting(0.0, unit="N m/rad", min=0)  # position stiffness
    k_d: float = setting(0.0, unit="N m s/rad", min=0)  # velocity damping
    k_i: float = setting(0.0, unit="1/s", min=0)  # torque integral gain (paper: 0)
    integral_limit: float = setting(10.0, unit="N m", min=0)  # anti-windup clamp of |k_i * integral(e_tau)|
    k_iq: float = setting(0.0, unit="1/s", min=0)  # position-integral rate, 1 / integral time (position_integral.py)
    position_integral_limit: float = setting(0.001, unit="rad", min=0)  # clamp of the position integral

    def __post_init__(self):
        check_settings(self, ControlError)


K7_SCALINGS = ("constant", "inverse_sqrt_k6")
"""``k7_scaling``: ``constant`` uses k7 (k_d) as given; ``inverse_sqrt_k6`` divides it by sqrt(K6), so the given
k7 is the value at K6 = 1 and lower stiffnesses get more velocity feedback (docs/control.md: the measured
stability window of k7 moves up as K6 falls)."""


@dataclass(frozen=True)
class ServoGains:
    """The keys of ``[defaults]`` and ``[joints.<name>]`` in the servo's terms, converted to :class:`JointGains`'
    ``k_s`` and ``k_d``: ``k6 = K_tau (1 + K_p) K_s``, ``k7 = K_tau (1 + K_p) K_d`` (either form, not both)."""

    k6: float | None = setting(None, unit="-, 1 = the native servo", min=0)
    k7: float | None = setting(None, unit="s", min=0)
    # K7 as a share of the joint's identified k_v (the servo's own damping, which the feedforward K_v dq_hat cancels
    # with a filtered velocity): k7 = k7_per_k_v * k_v, the tuning following the identified model
    k7_per_k_v: float | None = setting(None, unit="-", min=0)
    k7_scaling: str = setting("constant", choices=K7_SCALINGS)


@dataclass(frozen=True)
class ForceTask:
    """Force regulation on a frame of the foot or hand (paper section 5.4): ``f* = f_d + K_f (f_d - f_hat)``.

    The wrench is measured by F/T sensor ``sensor`` (HAL name) and expressed at ``frame`` (a frame of the
    robot model on the same body), moved by ``offset`` [m] in that frame (e.g. to the sole). Only ``axes``
    are regulated; the other axes of that wrench enter the feedforward as measured.
    """

    sensor: str = setting("right_ankle", choices=FT_SENSOR_NAMES)
    frame: str = setting("ft_right_ankle")
    axes: tuple[str, ...] = setting(AXES)
    k_f: tuple[float, ...] = setting((1.0,) * 6, unit="-", min=0)  # per axis (paper: 1)
    offset: tuple[float, float, float] = setting((0.0, 0.0, 0.0), unit="m")  # task point in ``frame``

    def __post_init__(self):
        axes = tuple(self.axes)
        if not axes or len(set(axes)) != len(axes) or any(a not in AXES for a in axes):
            raise ControlError(f"ForceTask.axes = {self.axes!r}: expected distinct names among {list(AXES)}")
        check_settings(self, ControlError)
        if len(self.k_f) != len(self.axes):
            raise ControlError(f"ForceTask.k_f = {self.k_f!r}: expected {len(axes)} values, one per axis {axes}")

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
    joint_limit_margin: float = setting(0.02, unit="rad", min=0)  # q must stay in [q_min + margin, q_max - margin]
    # The hold after a trip brakes: q_des = q_hold - hold_damping * dq (encoder backward difference), the term
    # faded to zero over hold_brake_time: damping the servo lacks, so a joint caught moving stops sooner.
    hold_damping: float = setting(0.01, unit="s", min=0)
    hold_brake_time: float = setting(0.2, unit="s", min=0)

    def __post_init__(self):
        n = None
        for name, unit in (("max_command_error", "rad"), ("max_torque", "N m"), ("max_velocity", "rad/s")):
            arr = np.array(getattr(self, name), dtype=float)
            n = arr.size if n is None else n
            if arr.ndim != 1 or arr.size != n or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                raise ControlError(f"SafetyLimits.{name} = {arr.tolist()}: expected {n} finite numbers > 0 [{unit}]")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        check_settings(self, ControlError)

    @classmethod
    def uniform(cls, n: int, **limits: float) -> SafetyLimits:
        """The same limits for all ``n`` joints: ``limits`` overrides the fields of :class:`JointLimits` and the
        scalar settings (``joint_limit_margin``, ``hold_*``), the others take their defaults."""
        scalars = {k: limits.pop(k) for k in SCALAR_SAFETY if k in limits}
        values = {f.name: limits.pop(f.name, f.default) for f in fields(JointLimits)}
        if limits:
            raise ControlError(f"SafetyLimits.uniform: unknown limits {sorted(limits)}: expected among "
                               f"{[f.name for f in fields(JointLimits)] + list(SCALAR_SAFETY)}")
        return cls(**{k: np.full(n, v) for k, v in values.items()}, **scalars)


SCALAR_SAFETY = ("joint_limit_margin", "hold_damping", "hold_brake_time")  # [safety] settings of every joint at once


@dataclass(frozen=True)
class JointLimits:
    """The limits of :class:`SafetyLimits` for one joint: ``[safety]`` (every joint) and
    ``[safety.joints.<name>]`` (its overrides)."""

    max_command_error: float = setting(0.05, unit="rad", min=0, strict_min=True)
    max_torque: float = setting(300.0, unit="N m", min=0, strict_min=True)
    max_velocity: float = setting(5.0, unit="rad/s", min=0, strict_min=True)

    def __post_init__(self):
        check_settings(self, ControlError)


@dataclass(frozen=True)
class ControlConfig:
    """Everything the controller needs besides the robot: gains, motor models, task, safety limits."""

    joint_names: tuple[str, ...]  # all joints, RobotInfo order
    gains: Mapping[str, JointGains]  # torque-controlled joints (the others stay position-controlled)
    motors: Mapping[str, MotorModel]  # identified actuator model of each torque-controlled joint
    safety: SafetyLimits
    base: str = setting("fixed", choices=BASES)
    contacts: tuple[str, ...] = setting(())  # F/T sensors whose measured wrench enters the feedforward (-J^T f_hat)
    force: ForceTask | None = None
    sign_velocity: float = setting(0.01, unit="rad/s", min=0, strict_min=True)  # Coulomb: k_c tanh(dq / this)
    fade_time: float = setting(0.5, unit="s", min=0)  # the bumpless-switch offset fades to zero over this time
    velocity_feedforward: str = setting("estimate", choices=VELOCITY_FEEDFORWARDS)  # velocity the feedforward reads
    rest_velocity: float = setting(0.001, unit="rad/s", min=0, strict_min=True)  # position integral while |dq_d| <
    # torque mode, the estimate invalid after more skipped frames than the estimator's max_gap: "position" =
    # position control (bumpless) until the estimate is valid again, then torque mode again; "trip" = a safety trip
    gap_fallback: str = setting("position", choices=("position", "trip"))
    # the position error K_s e_q reads: "estimate" = q_hat (the paper), "encoder" = the frame's measured q (the
    # last-sample filter's 2x peak near 20 Hz, fed back at K6 = 1, drives a servo with little damping unstable;
    # control/stability.py)
    position_feedback: str = setting("estimate", choices=("estimate", "encoder"))
    # k_p per joint: "fixed" = as configured; "margin" = lowered (halved, then 0) until the identified model's
    # loop keeps a margin on servos that differ from it (control/tuning.py tuned(), applied to every controller built
    # from a file: ControlManager.from_toml, tasks, experiments)
    gain_schedule: str = setting("fixed", choices=("fixed", "margin"))
    source: str = "<direct>"  # file the config came from
    _torque_mask: np.ndarray = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        check_settings(self, ControlError)
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
        contacts = tuple(self.contacts)
        for c in contacts:
            if c not in FT_SENSOR_NAMES:
                raise ControlError(f"contacts: {c!r} is not an F/T sensor: expected one of {list(FT_SENSOR_NAMES)}")
        if len(set(contacts)) != len(contacts):
            raise ControlError(f"contacts = {list(contacts)}: expected distinct sensors")
        object.__setattr__(self, "contacts", contacts)
        if self.force is not None and not isinstance(self.force, ForceTask):
            raise ControlError(f"force = {self.force!r}: expected a ForceTask or None")
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
        version = root.int("version")
        if version != FORMAT_VERSION:
            raise root.error("version", version, f"{FORMAT_VERSION}")
        motors_path = root.str("motors")
        try:
            motors_file = resolve_config_path(motors_path, root.file)
            params = MotorParameters.load_toml(motors_file)
            motors = dict(params.models)
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
            params.servo_model(j)  # a servo-error model with k_tau: else an error naming the file, joint and key
        if len(set(torque_joints)) != len(torque_joints):
            raise root.error("torque_joints", torque_joints, "distinct joint names")

        defaults = root.section("defaults", {})
        joints = root.section("joints", {})
        for j in joints.keys():
            if j not in torque_joints:
                raise joints.error(j, joints.data[j], f"a table for a joint listed in torque_joints {torque_joints}")
        base = _gain_tables(defaults)
        gains = {j: _joint_gains(joints.section(j, {}), defaults, base, motors[j]) for j in torque_joints}
        force = _force(root.section("force")) if "force" in root else None

        contacts = root.data.get("contacts", [])
        if (not isinstance(contacts, list) or len(set(map(str, contacts))) != len(contacts)
                or any(c not in FT_SENSOR_NAMES for c in contacts)):
            raise root.error("contacts", contacts, f"a list of distinct F/T sensors among {list(FT_SENSOR_NAMES)}")

        return load_dataclass(
            cls, root, ignore=["version", "motors", "torque_joints", "defaults", "joints", "force", "safety"],
            joint_names=names, gains=gains, motors={j: motors[j] for j in torque_joints},
            safety=_safety(root.section("safety", {}), info), force=force, source=root.file,
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
                one = replace(m, extra={name: term})
                checked_online_model(one, period)
            except IdentificationError as err:
                raise ConfigError(f"{file}: field '{field_}' (shape {dict(term.shape)}): joint \"{joint}\": {err}: "
                                  f"expected the shape parameters of effect '{name}'") from err


_GAIN_KEYS = tuple(f.name for f in fields(JointGains))
_SERVO_KEYS = tuple(f.name for f in fields(ServoGains))


def _gain_tables(sec: Section, base: tuple[JointGains, ServoGains] | None = None) -> tuple[JointGains, ServoGains]:
    """The gains of a ``[defaults]`` or ``[joints.<name>]`` table (missing keys: ``base``, else the defaults),
    k6/k7 not yet converted."""
    for a, b in (("k6", "k_s"), ("k7", "k_d"), ("k7_per_k_v", "k_d"), ("k7_per_k_v", "k7")):
        if a in sec and b in sec:
            raise sec.error(b, sec.data[b], f"either {a} or {b}, not both")
    gains = load_dataclass(JointGains, sec, ignore=_SERVO_KEYS, base=base and base[0])
    return gains, load_dataclass(ServoGains, sec, ignore=_GAIN_KEYS, base=base and base[1])


def _joint_gains(own: Section, defaults: Section, base: tuple[JointGains, ServoGains], motor: MotorModel) -> JointGains:
    """Gains of one joint: its own table first, then [defaults]; k6/k7 are converted to k_s/k_d (k7_per_k_v: k7
    from the joint's identified k_v), and k_d is divided by sqrt(K6) with ``k7_scaling = "inverse_sqrt_k6"``."""
    gains, servo = _gain_tables(own, base)
    k_tau = motor.k_tau

    def form(key: str, others: tuple[str, ...]) -> bool:
        # The joint's own table wins over [defaults], whichever of the forms each uses.
        return next((key in sec for sec in (own, defaults) if key in sec or any(o in sec for o in others)), False)

    k_s, k_d = gains.k_s, gains.k_d
    if form("k6", ("k_s",)):
        k_s = float(ks_from_k6(k_tau, gains.k_p, servo.k6)[0])
    if form("k7", ("k_d", "k7_per_k_v")):
        k_d = float(kd_from_k7(k_tau, gains.k_p, servo.k7)[0])
    elif form("k7_per_k_v", ("k_d", "k7")):
        k_d = float(kd_from_k7(k_tau, gains.k_p, servo.k7_per_k_v * motor.k_v)[0])
    if servo.k7_scaling == "inverse_sqrt_k6":
        k6 = k_tau * (1.0 + gains.k_p) * k_s
        if not k6 > 0:
            sec = own if "k7_scaling" in own else defaults
            raise sec.error("k7_scaling", servo.k7_scaling, "'constant' for a joint without position gain (k6 = 0)")
        k_d /= math.sqrt(k6)
    return replace(gains, k_s=k_s, k_d=k_d)


def _force(fs: Section) -> ForceTask:
    """``[force]``: sensor, frame and k_f are required in the file; axes must be distinct, one k_f per axis."""
    axes = fs.data.get("axes", list(AXES))
    if not isinstance(axes, list) or not axes or len(set(axes)) != len(axes) or any(a not in AXES for a in axes):
        raise fs.error("axes", axes, f"a list of distinct axes among {list(AXES)}")
    k_f = f"a list of {len(axes)} finite numbers [-]"
    for key, expected in (("k_f", k_f), ("sensor", f"one of {list(FT_SENSOR_NAMES)}"), ("frame", "a string")):
        if key not in fs:
            raise fs.missing(key, expected)
    if not isinstance(fs.data["k_f"], list) or len(fs.data["k_f"]) != len(axes):
        raise fs.error("k_f", fs.data["k_f"], k_f)
    return load_dataclass(ForceTask, fs)


def _safety(sec: Section, info: RobotInfo) -> SafetyLimits:
    """``[safety]``: the limits of every joint, ``[safety.joints.<name>]`` overrides, joint_limit_margin."""
    limits = load_dataclass(JointLimits, sec, ignore=[*SCALAR_SAFETY, "joints"])
    arrays = {f.name: np.full(info.nq, getattr(limits, f.name)) for f in fields(JointLimits)}
    per_joint = sec.section("joints", {})
    for j in per_joint.keys():
        if j not in info.joint_names:
            raise per_joint.error(j, per_joint.data[j], f"a table named after a joint of {info.name}, "
                                                        f"among {list(info.joint_names)}")
        own = load_dataclass(JointLimits, per_joint.section(j), base=limits)
        for k in arrays:
            arrays[k][info.joint_index(j)] = getattr(own, k)
    return load_dataclass(SafetyLimits, sec, ignore=[*arrays, "joints"], **arrays)
