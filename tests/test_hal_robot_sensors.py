"""Invalid encoders never crash the robot side and never let a command through; the operator's reset of a
latched servo-off (firmware, operator requests, the in-process backend), all in robot time."""

from __future__ import annotations

import json

import numpy as np
import pytest

from servotau.hal import (
    STATUS_INVALID,
    STATUS_OK,
    STATUS_STALE,
    Firmware,
    FirmwareState,
    InProcessBackend,
    SafetyConfig,
)
from servotau.hal.robot.firmware import checked_frame
from servotau.hal.robot.operator import parse_request
from servotau.hal.wire.protocol import FLAG_SENSOR_FAULT, FLAG_SERVO_OFF, decode_frame, encode_frame
from servotau.simrobot.fake import FakeRobot

INFO = FakeRobot().info
Q = np.full(INFO.nq, 0.01)
NAN = np.full(INFO.nq, np.nan)


def test_nan_encoders_hold_the_last_valid_reading_and_block_commands():
    """NaN encoders: the firmware holds each joint's last valid reading, applies no command (the position-error
    check cannot pass on NaN), flags SENSOR_FAULT; once valid again a fresh command resumes."""
    fw = Firmware(INFO, SafetyConfig(invalid_encoders_after=0.2))
    fw.accept(Q, 0.0)
    np.testing.assert_array_equal(fw.output(Q, 0.0), Q)
    for k in range(1, 100):  # 99 ms of NaN, commands keep coming far from the held posture
        fw.accept(Q + 0.05, k * 1e-3)
        out = fw.output(NAN, k * 1e-3, STATUS_INVALID)
        np.testing.assert_array_equal(out, Q)
    assert fw.state == FirmwareState.HOLDING and fw.flags & FLAG_SENSOR_FAULT and fw.sensor_fault
    # the command of tick 1 came before the fault was seen (accepted, then held); the 98 others were refused
    assert fw.counters["commands_during_sensor_fault"] == 98 and fw.counters["sensor_fault_ticks"] == 99
    assert fw.status()["hold_reason"] == "encoders invalid or stale"
    np.testing.assert_array_equal(fw.output(Q + 0.001, 0.1), Q)  # valid again: still holding, no command yet
    assert not fw.sensor_fault and fw.state == FirmwareState.HOLDING
    fw.accept(Q + 0.002, 0.101)
    np.testing.assert_array_equal(fw.output(Q + 0.001, 0.101), Q + 0.002)
    assert fw.state == FirmwareState.RUNNING


def test_one_nan_joint_holds_its_own_last_reading():
    """A NaN on one joint (status OK from a faulty robot): that joint holds its own last valid reading."""
    fw = Firmware(INFO)
    fw.accept(Q, 0.0)
    fw.output(Q, 0.0)
    q = Q + 0.001
    fw.output(q, 0.001)
    bad = q.copy()
    bad[7] = np.nan
    out = fw.output(bad, 0.002, STATUS_OK)
    assert out[7] == q[7] and np.isfinite(out).all() and fw.state == FirmwareState.HOLDING


def test_stale_encoders_hold_and_too_long_cuts_the_servos_latched():
    """A STALE status counts as invalid; invalid longer than invalid_encoders_after (robot ticks x period,
    whatever the caller's clock says): servo off (latched), never a NaN target; last_valid() stays finite for
    the robot's step."""
    fw = Firmware(INFO, SafetyConfig(invalid_encoders_after=0.05))
    fw.accept(Q, 0.0)
    fw.output(Q, 0.0)
    assert fw.output(Q, 10.0, STATUS_STALE) is not None and fw.state == FirmwareState.HOLDING  # a stalled clock
    for k in range(49):
        assert fw.output(Q, 10.0 + k, STATUS_STALE) is not None
    assert fw.output(NAN, 100.0, STATUS_INVALID) is None  # the 51st tick: 51 ms > 50 ms
    assert fw.state == FirmwareState.SERVO_OFF and fw.flags & FLAG_SERVO_OFF
    assert "encoders invalid or stale" in fw.status()["trip_reason"]
    np.testing.assert_array_equal(fw.last_valid(NAN), Q)


def test_encoders_never_valid_cut_the_servos():
    fw = Firmware(INFO)
    assert fw.output(NAN, 0.0, STATUS_INVALID) is None
    assert fw.state == FirmwareState.SERVO_OFF and "no valid encoder reading" in fw.servo_off_reason
    assert np.isfinite(fw.last_valid(NAN)).all()


def test_checked_frame_marks_non_finite_sensors_invalid():
    """A robot reporting NaN under status OK: the frame is published INVALID (decodable) instead."""
    f = FakeRobot().read()
    q = f.q.copy()
    q[2] = np.nan
    bad = checked_frame(type(f)(**{**f.__dict__, "q": q}))
    assert bad.status[0] == STATUS_INVALID and (bad.status[1:] == f.status[1:]).all()
    g, _ = decode_frame(encode_frame(bad), INFO.nq)
    assert np.isnan(g.q[2])
    assert checked_frame(f) is f


def test_inprocess_nan_encoders_keep_the_robot_side_up_then_reset():
    """FakeRobot's scripted NaN encoders (simrobot hook): the in-process robot side holds, then cuts the servos
    after invalid_encoders_after of robot time, keeps stepping with finite angles, and the operator's reset
    (once the encoders are valid) turns them back on; a controller then commands again."""
    robot = FakeRobot(encoder_faults=[{"kind": "nan", "start": 0.05, "duration": 0.3}])
    with InProcessBackend(robot, SafetyConfig(invalid_encoders_after=0.1)) as b:
        f0 = b.read()
        for _ in range(200):
            f = b.read()
            b.write_array(f0.q)
        st = b.status()
        assert st["state"] == "SERVO_OFF" and "encoders" in st["trip_reason"] and np.isnan(f.q).all()
        assert f.status[0] == STATUS_INVALID
        assert np.isfinite(robot.applied).all()  # the simulator never got a NaN
        answer = b.operator({"action": "reset"})
        assert answer["ok"] is False and "encoders invalid" in answer["error"] and answer["state"] == "SERVO_OFF"
        while b.read().time < 0.36:  # servos off, the robot keeps stepping; the fault ends at 0.35 s
            pass
        assert b.operator({"action": "reset"}) == {"ok": True, "state": "WAITING", "error": None}
        assert robot._off is False and b.status()["resets"] == 1 and b.robot_state == "waiting"
        f = b.read()
        b.write_array(f.q)
        b.read()
        assert b.robot_state == "running" and b.status()["trip_reason"].startswith("encoders")


def test_reset_of_a_position_error_trip():
    fw = Firmware(INFO, SafetyConfig(max_velocity=1e3, max_acceleration=1e9))
    fw.accept(Q + 0.2, 0.0)
    assert fw.output(Q, 0.0) is None and fw.state == FirmwareState.SERVO_OFF
    assert fw.reset(Q) == (True, None)
    np.testing.assert_array_equal(fw.output(Q + 0.001, 0.001), Q)  # holds the position at the reset
    assert fw.state == FirmwareState.WAITING and fw.status()["servo_off_reason"] is None
    assert "|q_des - q|" in fw.status()["trip_reason"]
    assert Firmware(INFO).reset(Q) == (True, None)  # nothing latched: nothing to do


@pytest.mark.parametrize(("payload", "error"), [
    (None, "empty request"),
    (b"", "empty request"),
    (b"\xff\xfe", "not JSON"),
    (b"[1, 2]", 'with the key "action"'),
    (json.dumps({"action": "reset", "x": 1}).encode(), "request keys ['x'] with action 'reset'"),
    (json.dumps({"action": "explode"}).encode(), "action = 'explode': expected one of ['reset']"),
    (b"{" * 5000, "at most 4096"),
])
def test_bad_operator_requests_are_answered_with_an_error(payload, error):
    action, err = parse_request(payload)
    assert action is None and error in err
    with InProcessBackend(FakeRobot()) as b:
        answer = b.operator(payload if payload is not None else b"")
        assert answer["ok"] is False and answer["state"] == "WAITING" and answer["error"]
