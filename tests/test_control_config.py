"""Tests of servotau.control.config: config/control.toml and the validation of every field."""

import copy
import math
import tomllib

import numpy as np
import pytest

from servotau.config import CONFIG_DIR
from servotau.control.config import ControlConfig, ForceTask, JointGains, SafetyLimits
from servotau.description import JOINT_NAMES, MODEL_PATH
from servotau.errors import ConfigError, ControlError
from servotau.hal.types import RobotInfo

INFO = RobotInfo("test-robot", JOINT_NAMES, -np.full(30, 3.0), np.full(30, 3.0), 1e-3, str(MODEL_PATH))
with open(CONFIG_DIR / "control.toml", "rb") as _f:
    BASE = tomllib.load(_f)
with open(CONFIG_DIR / BASE["motors"], "rb") as _f:
    K_TAU = {j: m["k_tau"] for j, m in tomllib.load(_f)["joints"].items()}  # the shipped motor file's values


def _with(path: str, value):
    """The shipped config with ``path`` (dotted) set to ``value`` (or removed if value is ...)."""
    data = copy.deepcopy(BASE)
    keys = path.split(".")
    d = data
    for k in keys[:-1]:
        d = d.setdefault(k, {})
    if value is ...:
        d.pop(keys[-1], None)
    else:
        d[keys[-1]] = value
    return data


def test_shipped_config_loads_with_k6_converted_to_stiffness():
    """config/control.toml loads: the right leg is torque-controlled and k6 becomes k_s = k6/(k_tau (1 + k_p))."""
    cfg = ControlConfig.from_toml("control.toml", INFO)
    assert cfg.torque_joints == tuple(f"RLEG_JOINT{i}" for i in range(6))
    assert cfg.torque_mask.sum() == 6 and cfg.torque_mask[:6].all()
    g = cfg.gains["RLEG_JOINT3"]
    k6 = BASE["defaults"]["k6"]
    assert g.k_s == pytest.approx(k6 / (K_TAU["RLEG_JOINT3"] * (1.0 + g.k_p)))
    assert cfg.joint_vector("k_s")[6:].tolist() == [0.0] * 24
    assert cfg.motor_vector("k_tau")[3] == K_TAU["RLEG_JOINT3"]
    assert cfg.joint_vector("k_iq")[:6].tolist() == [BASE["defaults"]["k_iq"]] * 6  # the position integral is on
    assert cfg.joint_vector("k_iq")[6:].tolist() == [0.0] * 24 and cfg.rest_velocity == BASE["rest_velocity"]


def test_joint_table_overrides_defaults_in_either_unit():
    """A [joints.X] table overrides [defaults]; k_s given in SI is kept as is, k6 is converted."""
    data = _with("joints", {"RLEG_JOINT3": {"k_s": 1234.0, "k_p": 2.0}, "RLEG_JOINT2": {"k6": 0.5, "k_p": 2.0}})
    cfg = ControlConfig.from_mapping(data, INFO)
    assert cfg.gains["RLEG_JOINT3"].k_s == 1234.0
    assert cfg.gains["RLEG_JOINT3"].k_p == 2.0
    assert cfg.gains["RLEG_JOINT2"].k_s == pytest.approx(0.5 / (K_TAU["RLEG_JOINT2"] * 3.0))


def test_k7_scaling_divides_the_velocity_gain_by_sqrt_k6():
    """k7_scaling = "inverse_sqrt_k6": K7 = k7 / sqrt(K6) per joint (the given k7 is the value at K6 = 1);
    "constant" keeps k7; a joint table overrides [defaults]."""
    data = _with("defaults.k6", 0.25)
    data["defaults"].pop("k7_per_k_v", None)  # the shipped form; k7 [s] instead
    data["defaults"].update({"k7": 0.001, "k7_scaling": "inverse_sqrt_k6"})
    data["joints"] = {"RLEG_JOINT2": {"k7_scaling": "constant"}}
    cfg = ControlConfig.from_mapping(data, INFO)

    def k7(joint):
        g = cfg.gains[joint]
        return K_TAU[joint] * (1.0 + g.k_p) * g.k_d

    assert k7("RLEG_JOINT3") == pytest.approx(0.002)
    assert k7("RLEG_JOINT2") == pytest.approx(0.001)
    assert BASE["defaults"]["k7_scaling"] == "constant"  # the shipped rule: k7 = k_v at every K6


@pytest.mark.parametrize("path, value, field, expected", [
    ("defaults.k_p", -2.0, "defaults.k_p", ">= 0"),
    ("defaults.k6", math.nan, "defaults.k6", "finite"),
    ("defaults.k_i", "high", "defaults.k_i", "finite number"),
    ("defaults.k_iq", -2.0, "defaults.k_iq", ">= 0"),
    ("joints", {"RLEG_JOINT0": {"position_integral_limit": math.nan}}, "joints.RLEG_JOINT0.position_integral_limit",
     "finite"),
    ("rest_velocity", 0.0, "rest_velocity", "> 0"),
    ("joints", {"RLEG_JOINT3": {"k_d": -1.0}}, "joints.RLEG_JOINT3.k_d", ">= 0"),
    ("joints", {"RLEG_JOINT3": {"k6": 1.0, "k_s": 10.0}}, "joints.RLEG_JOINT3.k_s", "either k6 or k_s"),
    ("joints", {"LARM_JOINT0": {}}, "joints.LARM_JOINT0", "torque_joints"),
    ("joints", {"RLEG_JOINT3": {"kp": 2.0}}, "joints.RLEG_JOINT3.kp", "known field"),
    ("torque_joints", ["RLEG_JOINT3", "NOT_A_JOINT"], "torque_joints", "joints of test-robot"),
    ("torque_joints", ["LLEG_JOINT3"], "torque_joints", "motor model"),
    ("base", "wobbly", "base", "fixed"),
    ("sign_velocity", 0.0, "sign_velocity", "> 0"),
    ("fade_time", -1.0, "fade_time", ">= 0"),
    ("velocity_feedforward", "measured", "velocity_feedforward", "'estimate', 'reference'"),
    ("defaults.k7_scaling", "inverse_k6", "defaults.k7_scaling", "'constant', 'inverse_sqrt_k6'"),
    ("joints", {"RLEG_JOINT3": {"k6": 0.0, "k7_scaling": "inverse_sqrt_k6"}}, "k7_scaling",
     "'constant' for a joint without position gain"),
    ("contacts", ["left_knee"], "contacts", "F/T sensors"),
    ("safety.max_torque", -5.0, "safety.max_torque", "> 0"),
    ("safety.max_velocity", math.inf, "safety.max_velocity", "finite"),
    ("safety.hold_damping", -0.01, "safety.hold_damping", ">= 0"),
    ("safety.hold_brake_time", math.nan, "safety.hold_brake_time", "finite"),
    ("safety.joints", {"KNEE": {"max_torque": 10.0}}, "safety.joints.KNEE", "joint of test-robot"),
    ("force", {"sensor": "right_ankle", "frame": "ft_right_ankle", "axes": ["fz", "fw"], "k_f": [1.0, 1.0]},
     "force.axes", "distinct axes"),
    ("force", {"sensor": "right_ankle", "frame": "ft_right_ankle", "axes": ["fz"], "k_f": [-1.0]},
     "force.k_f", ">= 0"),
    ("version", 2, "version", "1"),
    ("motors", "motors/missing.toml", "motors", "not found"),
])
def test_bad_field_names_the_field_and_the_expected_value(path, value, field, expected):
    """Negative, NaN, mistyped or unknown values raise ConfigError naming the file, the field and what was expected."""
    with pytest.raises(ConfigError) as info:
        ControlConfig.from_mapping(_with(path, value), INFO, file="ctl.toml")
    msg = str(info.value)
    assert "ctl.toml" in msg and field in msg and expected in msg, msg


@pytest.mark.parametrize("build, field", [
    (lambda: JointGains(k_p=-1.0), "JointGains.k_p"),
    (lambda: JointGains(k_s=float("nan")), "JointGains.k_s"),
    (lambda: JointGains(k_iq=-1.0), "JointGains.k_iq"),
    (lambda: ControlConfig(JOINT_NAMES, {}, {}, SafetyLimits.uniform(30), rest_velocity=-1e-3), "rest_velocity"),
    (lambda: ForceTask(axes=("fz",), k_f=(1.0, 2.0)), "ForceTask.k_f"),
    (lambda: ForceTask(sensor="nose"), "ForceTask.sensor"),
    (lambda: SafetyLimits.uniform(30, max_torque=0.0), "SafetyLimits.max_torque"),
    (lambda: ControlConfig(JOINT_NAMES, {"RLEG_JOINT3": JointGains()}, {}, SafetyLimits.uniform(30)), "motor model"),
    (lambda: ControlConfig(JOINT_NAMES, {"KNEE": JointGains()}, {}, SafetyLimits.uniform(30)), "KNEE"),
    (lambda: ControlConfig(JOINT_NAMES, {}, {}, SafetyLimits.uniform(30), velocity_feedforward="desired"),
     "velocity_feedforward"),
])
def test_direct_construction_is_validated(build, field):
    """The dataclasses built in code raise ControlError naming the field and the expected value."""
    with pytest.raises(ControlError, match=field) as info:
        build()
    assert "expected" in str(info.value)


def test_defaults_live_in_the_dataclass_fields():
    """Fields absent from the file take the dataclasses' defaults; [safety.joints.X] overrides one joint."""
    data = _with("safety.joints", {"HEAD_JOINT0": {"max_torque": 20.0}})
    for key in ("sign_velocity", "fade_time", "velocity_feedforward", "rest_velocity"):
        data.pop(key)
    data["safety"].pop("max_velocity")
    cfg = ControlConfig.from_mapping(data, INFO)
    direct = ControlConfig(JOINT_NAMES, {}, {}, SafetyLimits.uniform(30))
    for key in ("sign_velocity", "fade_time", "velocity_feedforward", "rest_velocity"):
        assert getattr(cfg, key) == getattr(direct, key)
    head = INFO.joint_index("HEAD_JOINT0")
    assert cfg.safety.max_torque[head] == 20.0 and cfg.safety.max_torque[0] == BASE["safety"]["max_torque"]
    assert (cfg.safety.max_velocity == direct.safety.max_velocity).all()
    assert cfg.safety.max_command_error[head] == BASE["safety"]["max_command_error"]


def test_force_table_requires_sensor_frame_and_gains():
    """The [force] table names its sensor, frame and k_f (one per axis); offset and axes may be left out."""
    task = {"sensor": "right_ankle", "frame": "ft_right_ankle", "k_f": [1.0] * 6}
    assert ControlConfig.from_mapping(_with("force", task), INFO).force == ForceTask()
    for key in task:
        with pytest.raises(ConfigError, match=rf"ctl.toml: field 'force.{key}' missing: expected"):
            ControlConfig.from_mapping(_with("force", {k: v for k, v in task.items() if k != key}), INFO, "ctl.toml")
    with pytest.raises(ConfigError, match=r"field 'force.k_f' = \[1.0\]: expected a list of 6 finite numbers"):
        ControlConfig.from_mapping(_with("force", {**task, "k_f": [1.0]}), INFO, "ctl.toml")
