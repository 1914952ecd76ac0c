"""Robot-side firmware: watchdog hold (indefinite, or servo off when set), |q_des - q| trip, clamping, counters
(rate limits, sensor faults, reset: tests/test_hal_robot_limits.py, tests/test_hal_robot_sensors.py)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from servotau.config import Section
from servotau.errors import ConfigError, HalError
from servotau.hal import Firmware, FirmwareState, SafetyConfig
from servotau.simrobot.fake import FakeRobot

INFO = FakeRobot().info
Q = np.zeros(INFO.nq)
FAST = {"max_velocity": 1e3, "max_acceleration": 1e8}  # rate limits out of the way of the other checks


def test_waits_holding_the_first_position_without_timeout():
    """Before any command the robot holds its first measured position, however long it waits."""
    fw = Firmware(INFO, SafetyConfig(hold_after=0.01, servo_off_after=0.02))
    q0 = np.full(INFO.nq, 0.05)
    np.testing.assert_array_equal(fw.output(q0, 0.0), q0)
    np.testing.assert_array_equal(fw.output(q0 + 0.01, 100.0), q0)
    assert fw.state == FirmwareState.WAITING


def test_watchdog_holds_then_cuts_servos_latched():
    """No fresh command: hold the measured position after hold_after, servo off after servo_off_after (without
    braking: exactly the measured position)."""
    fw = Firmware(INFO, SafetyConfig(hold_after=0.05, servo_off_after=0.2, hold_damping=0.0, **FAST))
    fw.accept(Q + 0.02, 0.0)
    np.testing.assert_array_equal(fw.output(Q, 0.04), Q + 0.02)
    held = fw.output(Q + 0.01, 0.06)  # measured position at the trip
    assert fw.state == FirmwareState.HOLDING and fw.counters["holds"] == 1
    np.testing.assert_array_equal(held, Q + 0.01)
    np.testing.assert_array_equal(fw.output(Q + 0.015, 0.1), Q + 0.01)
    assert fw.output(Q, 0.21) is None and fw.state == FirmwareState.SERVO_OFF
    fw.accept(Q, 0.22)  # latched: a late command changes nothing
    assert fw.output(Q, 0.23) is None and fw.counters["commands_after_servo_off"] == 1
    assert "no fresh command" in fw.servo_off_reason


def test_fresh_command_resumes_from_hold_and_controller_loss_holds_at_once():
    """A fresh command ends a hold; a vanished controller token holds at the next tick."""
    fw = Firmware(INFO, SafetyConfig(hold_after=0.05, **FAST))
    fw.accept(Q, 0.0)
    fw.output(Q, 0.1)
    assert fw.state == FirmwareState.HOLDING
    fw.accept(Q + 0.01, 0.2)
    np.testing.assert_array_equal(fw.output(Q, 0.2), Q + 0.01)
    fw.controller_lost()
    fw.output(Q + 0.003, 0.201)
    assert fw.state == FirmwareState.HOLDING


def test_position_error_trips_servo_off():
    """|q_des - q| beyond max_position_error on one joint cuts the servos (latched), naming the joint."""
    fw = Firmware(INFO, SafetyConfig(**FAST))
    q_des = Q.copy()
    q_des[4] = INFO.max_position_error + 0.01
    fw.accept(q_des, 0.0)
    assert fw.output(Q, 0.0) is None
    assert 'joint "J04"' in fw.servo_off_reason and fw.state == FirmwareState.SERVO_OFF
    fw.accept(Q, 0.001)
    assert fw.output(Q, 0.001) is None


def test_clamps_to_joint_limits_with_rate_limited_warning(caplog):
    """Commands beyond the joint limits are clamped; the warning is rate limited."""
    fw = Firmware(INFO, SafetyConfig(max_position_error=10.0, warn_interval=60.0, **FAST))
    q_des = Q.copy()
    q_des[1] = 3.0
    with caplog.at_level(logging.WARNING, logger="servotau.hal.robot.firmware"):
        for k in range(100):
            fw.accept(q_des, k * 1e-3)
            out = fw.output(Q, k * 1e-3)
    assert out[1] == INFO.q_max[1] and fw.counters["clamped_ticks"] == 100 and fw.clamped
    assert len([r for r in caplog.records if "clamped" in r.message]) == 1


def test_reject_counts_and_rate_limits(caplog):
    """Rejected commands are counted one by one and logged at a limited rate."""
    fw = Firmware(INFO, SafetyConfig(warn_interval=60.0))
    with caplog.at_level(logging.WARNING, logger="servotau.hal.robot.firmware"):
        for _ in range(1000):
            fw.reject("counts", "bad")
        fw.reject("version", "old")
    assert fw.counters["commands_rejected"] == 1001 and fw.counters["commands_rejected_version"] == 1
    assert fw.status()["rejected"]["counts"] == 1000 and fw.status()["rejected"]["version"] == 1
    assert len(caplog.records) == 1


def test_safety_config_validation():
    """Bad safety settings are refused; from_section names the file and the field."""
    with pytest.raises(HalError, match="servo_off_after"):
        SafetyConfig(hold_after=0.1, servo_off_after=0.05)
    with pytest.raises(ConfigError, match="hal.toml: field 'safety.hold_after' = -1"):
        SafetyConfig.from_section(Section({"hold_after": -1}, "hal.toml", "safety"))
    s = SafetyConfig.from_section(Section({"hold_after": 0.02, "max_position_error": 0.2}, "x.toml", ""))
    assert s.hold_after == 0.02 and s.max_position_error == 0.2 and s.servo_off_after is None


def test_safety_config_bounds_name_the_other_field():
    """servo_off_after must exceed hold_after (from the file or its default): the message names both."""
    with pytest.raises(ConfigError, match=r"hal.toml: field 'safety.servo_off_after' = 1.0: expected a finite "
                                          r"number > hold_after = 2 \[s\]"):
        SafetyConfig.from_section(Section({"hold_after": 2.0, "servo_off_after": 1.0}, "hal.toml", "safety"))
    with pytest.raises(HalError, match=r"SafetyConfig.lockstep_servo_off_after = 0.5: expected a finite number > "
                                       r"lockstep_hold_after = 1 \[s\]"):
        SafetyConfig(lockstep_hold_after=1.0, lockstep_servo_off_after=0.5)
    assert SafetyConfig.from_section(Section({}, "x.toml", "")) == SafetyConfig()


def test_holds_indefinitely_without_a_controller():
    """No fresh command: the robot holds the measured position for as long as its encoders are valid (one hour
    of robot time here), never cutting the servos; a fresh command still resumes."""
    fw = Firmware(INFO)
    fw.accept(Q + 0.001, 0.0)
    fw.output(Q, 0.0)
    for t in np.arange(0.1, 3600.0, 0.5):
        out = fw.output(Q + 0.0005, t)
        assert out is not None
    assert fw.state == FirmwareState.HOLDING and fw.counters["holds"] == 1 and fw.counters["trips"] == 0
    np.testing.assert_array_equal(out, Q + 0.0005)  # the position measured when the hold began
    assert "no fresh command" in fw.status()["hold_reason"]
    fw.accept(Q + 0.0006, 3600.0)
    np.testing.assert_array_equal(fw.output(Q + 0.0005, 3600.0), Q + 0.0006)
    assert fw.state == FirmwareState.RUNNING


def test_lockstep_watchdog_holds_within_50ms_by_default():
    """A hung controller in lock-step: the shipped watchdog holds after 35 ms (of the caller's clock), so
    within 50 ms."""
    s = SafetyConfig().for_lockstep()
    assert s.hold_after == 0.035 and s.servo_off_after is None
    fw = Firmware(INFO, s)
    fw.accept(Q, 0.0)
    fw.output(Q, 0.0)
    fw.output(Q, 0.034)
    assert fw.state == FirmwareState.RUNNING
    fw.output(Q, 0.036)
    assert fw.state == FirmwareState.HOLDING
