"""Tests of `servotau identify run` (servotau/apps/identify.py, identification/motor_file.py) and of the servo and
motor files `servotau experiment --servo --motors` refuses before anything moves."""

import json
import re
from pathlib import Path

import pytest
from support.identification import SHORT_PLAN

from servotau.actuator import MotorParameters
from servotau.apps.operator_script import write_sim_setup
from servotau.cli import main as cli
from servotau.config import CONFIG_DIR
from servotau.identification.plan import load_plan

SERVO = (CONFIG_DIR / "servo.toml").read_text()


def servo_file(tmp_path: Path, old: str = "", new: str = "") -> Path:
    p = tmp_path / "servo.toml"
    assert old in SERVO
    p.write_text(SERVO.replace(old, new, 1))
    return p


@pytest.mark.parametrize("old, new, message", [
    ('joints = ["RLEG_JOINT3", "LLEG_JOINT3"]', 'joints = ["LLEG_JOINT3"]',
     r"servo\.toml: field 'groups\.\*\.kp'.*'RLEG_JOINT3'"),
    ("kp = 19608.0", "kp = -19608.0", r"servo\.toml: field 'groups\.knee\.kp'.*expected .*> 0"),
    ("kd = 86.0", "kd = -86.0", r"field 'groups\.knee\.kd'.*expected .*>= 0"),
])
def test_run_refuses_a_bad_servo_file_before_collecting(tmp_path, capsys, old, new, message):
    """A servo file with a joint missing or a negative gain: exit 2 naming the file, the field (and the joint);
    nothing is collected."""
    out = tmp_path / "motors.toml"
    assert cli(["identify", "run", "--servo", str(servo_file(tmp_path, old, new)), "--out", str(out)]) == 2
    assert re.search(message, capsys.readouterr().err)
    assert not out.exists() and not out.with_suffix(".parquet").exists()


def test_run_refuses_servo_with_a_robot_backend(tmp_path, capsys):
    assert cli(["identify", "run", "--servo", str(servo_file(tmp_path)), "--backend", "zenoh",
                "--out", str(tmp_path / "m.toml")]) == 2
    assert "expected --backend inprocess" in capsys.readouterr().err


def _without_knee(text: str) -> str:
    head, rest = text.split("[joints.RLEG_JOINT3]", 1)
    return head + "[joints.RLEG_JOINT4]" + rest.split("[joints.RLEG_JOINT4]", 1)[1]


def _negative_damping(text: str) -> str:
    """The knee's model with k_v < 0: negative damping, a loop the model itself predicts unstable."""
    head, rest = text.split("[joints.RLEG_JOINT3]", 1)
    line = next(v for v in rest.splitlines() if v.startswith("k_v = "))
    return head + "[joints.RLEG_JOINT3]" + rest.replace(line, "k_v = -0.001", 1)


@pytest.mark.parametrize("edit, message", [
    (_without_knee, r"torque_joints.*RLEG_JOINT3.*expected joints with a motor model"),
    (_negative_damping, r"joints\.RLEG_JOINT3\.k_v.*-0\.001.*expected"),
])
def test_experiment_refuses_a_bad_motor_file_before_anything_moves(tmp_path, capsys, edit, message):
    """A motor file without a torque joint, or whose model has negative damping: exit 2, the joint and field
    named (a model predicting a ringing loop at the gains: tests/test_control_tuning.py)."""
    bad = tmp_path / "motors.toml"
    bad.write_text(edit((CONFIG_DIR / "motors" / "hrp2_sim_identified.toml").read_text()))
    out = tmp_path / "out"
    assert cli(["experiment", "motion", "--motors", str(bad), "--out", str(out)]) == 2
    assert re.search(message, capsys.readouterr().err)
    assert not out.exists()


@pytest.mark.slow
def test_run_writes_the_controllers_motor_file_with_each_joints_choice(tmp_path, capsys):
    """The whole chain on a short plan (two joints) with a servo of other gains: the motor file loads, the
    controller's check passes, and the report gives each joint's choice and reason."""
    plan = tmp_path / "plan.toml"
    plan.write_text(SHORT_PLAN)
    sim = write_sim_setup(load_plan(plan)[0], tmp_path)
    servo = servo_file(tmp_path, "kp = 19608.0", "kp = 14000.0")
    out = tmp_path / "motors.toml"
    assert cli(["identify", "run", "--servo", str(servo), "--plan", str(plan), "--sim-config", str(sim),
                "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    params = MotorParameters.load_toml(out)
    assert set(report["joints"]) == set(params) == {"RLEG_JOINT2", "RLEG_JOINT3"}
    # the knee's servo gain is 14000 N m/rad: the identified k_tau follows it (asymmetric fit: a little below)
    assert 0.8 / 14000 < params["RLEG_JOINT3"].k_tau < 1.1 / 14000
    for j, c in report["joints"].items():
        assert c["reason"] and set(c["effects"]) <= {"coulomb", "deadzone", "stribeck"}
        assert ("deadzone" in params[j].extra) == (c["dead_band_kept"] or "deadzone" in c["effects"])
    header = out.read_text().split("version = 1")[0]
    assert "servotau identify run" in header and "RLEG_JOINT3:" in header


def test_experiment_refuses_a_bad_servo_file_before_anything_moves(tmp_path, capsys):
    out = tmp_path / "out"
    servo = servo_file(tmp_path, "kp = 19608.0", "kp = -19608.0")
    assert cli(["experiment", "force", "--servo", str(servo), "--out", str(out)]) == 2
    assert re.search(r"servo\.toml: field 'groups\.knee\.kp'", capsys.readouterr().err)
    assert not out.exists()
