"""COMMAND_HOLD (docs/protocol.md "State machine"): a tripped controller's commands ask the robot to hold; the
firmware holds at once from its own measurements (the posture of the frame the command answers, braking), keeps
the hold while the flag comes, and resumes on a command without it; lock-step still steps once per command."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import FRAME_TIMEOUT
from support.hal import endpoint, free_port, robot_server

from servotau.hal import Firmware, FirmwareState, SafetyConfig, ZenohBackend
from servotau.hal.backends.inprocess import InProcessBackend
from servotau.hal.errors import MalformedMessage
from servotau.hal.wire.protocol import HEADER_SIZE, decode_command, encode_command
from servotau.simrobot.fake import FakeRobot

INFO = FakeRobot().info
NAMES = INFO.joint_names
FAST = {"max_velocity": 1e3, "max_acceleration": 1e8}  # rate limits out of the way


def test_the_hold_flag_round_trips_and_other_flag_bits_are_rejected():
    q = np.zeros(INFO.nq)
    assert decode_command(encode_command(3, 0.003, q, hold=True), NAMES).hold is True
    assert decode_command(encode_command(3, 0.003, q), NAMES).hold is False
    buf = bytearray(encode_command(3, 0.003, q, hold=True))
    buf[6] |= 2
    with pytest.raises(MalformedMessage, match="flags") as exc:
        decode_command(bytes(buf), NAMES)
    assert exc.value.reason == "flags" and len(buf) > HEADER_SIZE


def test_a_hold_command_holds_the_answered_frames_posture_braking_then_resumes_without_the_flag():
    """Running, the joints moving 1 mrad per tick: a hold command answering the frame 2 ticks old holds that frame's
    posture (not its q_des, not the newest reading), braking against the motion; without damping exactly there."""
    for damping in (0.01, 0.0):
        fw = Firmware(INFO, SafetyConfig(hold_damping=damping, **FAST))
        for k in range(5):
            fw.accept(np.full(INFO.nq, 1e-3 * (k + 1)), float(k))
            fw.output(np.full(INFO.nq, 1e-3 * k), float(k))
        fw.accept(np.full(INFO.nq, 0.5), 5.0, hold=True, age=2)
        out = fw.output(np.full(INFO.nq, 5e-3), 5.0)  # this tick's frame: 2 ticks newer than the answered one (3e-3)
        assert fw.state == FirmwareState.HOLDING and fw.hold_commanded and "COMMAND_HOLD" in fw.hold_reason
        if damping:  # q_hold - 0.01 s * 1 rad/s
            np.testing.assert_allclose(out, 3e-3 - 1e-2, atol=1e-12)
        else:
            np.testing.assert_allclose(out, 3e-3, atol=1e-12)
        for k in range(6, 400):  # more hold commands (their q_des ignored) feed the watchdog: still held there
            fw.accept(np.full(INFO.nq, 0.5), k * 1e-3, hold=True)
            out = fw.output(np.full(INFO.nq, 3e-3), k * 1e-3)
        np.testing.assert_allclose(out, 3e-3, atol=1e-12)  # braking over
        assert fw.counters["hold_commands"] == 395 and fw.counters["holds"] == 1
        fw.accept(np.full(INFO.nq, 4e-3), 0.4)  # the operator reset the controller: its commands resume the run
        np.testing.assert_allclose(fw.output(np.full(INFO.nq, 3e-3), 0.4), 4e-3)
        assert fw.state == FirmwareState.RUNNING and not fw.hold_commanded


def test_a_hold_command_in_the_tick_an_encoder_fault_starts_keeps_the_faults_plain_hold():
    """The controller trips in the tick one encoder fails (NaN): the fault's hold stands, the last valid reading of
    every joint, not braked from the firmware's own velocity (no brake after an encoder fault), and the reason
    names both."""
    fw = Firmware(INFO, SafetyConfig(hold_damping=0.01, **FAST))
    for k in range(5):
        fw.accept(np.full(INFO.nq, 1e-3 * (k + 1)), float(k))
        fw.output(np.full(INFO.nq, 1e-3 * k), float(k))
    fw.accept(np.full(INFO.nq, 0.5), 5.0, hold=True, age=2)
    q = np.full(INFO.nq, 5e-3)
    q[0] = np.nan
    out = fw.output(q, 5.0)
    assert fw.state == FirmwareState.HOLDING and fw.sensor_fault
    assert "encoders invalid" in fw.hold_reason and "COMMAND_HOLD" in fw.hold_reason, fw.hold_reason
    expected = np.full(INFO.nq, 5e-3)
    expected[0] = 4e-3  # joint 0's last valid reading
    np.testing.assert_allclose(out, expected, atol=1e-12)
    np.testing.assert_allclose(fw.output(q, 5.001), expected, atol=1e-12)  # and it stays there


@pytest.mark.parametrize("age", [1, 5, 40])
def test_a_commanded_holds_first_step_stays_within_half_the_position_error_trip(age):
    """Joints moving at up to 10 rad/s, a hold command answering a frame ``age`` ticks old, strong braking
    (hold_damping 1 s): the first held q_des is within half of ``max_position_error`` of the measured angles (a
    quarter for the answered posture, a quarter for the brake), so the hold itself never trips the servos."""
    fw = Firmware(INFO, SafetyConfig(hold_damping=1.0, **FAST))
    v = np.linspace(-10.0, 10.0, INFO.nq)  # [rad/s]
    dt = INFO.period
    for k in range(60):
        fw.accept(v * dt * (k + 1), k * dt)
        fw.output(v * dt * k, k * dt)
    fw.accept(np.zeros(INFO.nq), 60 * dt, hold=True, age=age)
    q = v * dt * 60
    out = fw.output(q, 60 * dt)
    assert fw.state == FirmwareState.HOLDING
    step = np.abs(out - q)
    assert step.max() <= 0.5 * fw.max_error + 1e-12, (step.max(), fw.max_error)
    assert step.max() > 0.25 * fw.max_error  # the bound is reached here: the test exercises it


def test_a_silent_holding_controller_leaves_a_plain_hold_and_a_claim_end_too():
    fw = Firmware(INFO, SafetyConfig(hold_after=0.01, **FAST))
    fw.accept(np.zeros(INFO.nq), 0.0)
    fw.output(np.zeros(INFO.nq), 0.0)
    fw.accept(np.zeros(INFO.nq), 0.001, hold=True)
    fw.output(np.zeros(INFO.nq), 0.001)
    assert fw.hold_commanded
    fw.output(np.zeros(INFO.nq), 0.02)
    assert fw.state == FirmwareState.HOLDING and not fw.hold_commanded and "no fresh command" in fw.hold_reason
    fw.accept(np.zeros(INFO.nq), 0.021, hold=True)
    fw.controller_lost()
    assert fw.state == FirmwareState.HOLDING and not fw.hold_commanded


def test_set_hold_on_a_backend_makes_its_commands_hold_the_robot():
    robot = FakeRobot()
    with InProcessBackend(robot, SafetyConfig(**FAST)) as b:
        f = b.read()
        b.write({"J00": f.q[0] + 0.01})
        b.read()
        b.set_hold(True)
        b.write({"J00": f.q[0] + 0.05})  # not applied: the robot holds
        held = robot.applied[-1].copy()
        assert b.robot_state == "holding" and b.firmware.hold_commanded and held[0] < f.q[0] + 0.01
        b.read()
        b.set_hold(False)
        b.write({"J00": f.q[0] + 0.01})
        assert b.robot_state == "running" and robot.applied[-1][0] == f.q[0] + 0.01


def test_lockstep_steps_once_per_hold_command_and_resumes(tmp_path):
    """Over Zenoh in lock-step: each hold command steps the robot once (the watchdog fed, no stepping of its own),
    the robot holds instead of the command, and a command without the flag resumes RUNNING."""
    port = free_port()
    with robot_server(tmp_path, port, lockstep_hold_after=1.0):
        with ZenohBackend("fake", connect=[endpoint(port)], frame_timeout=FRAME_TIMEOUT) as b:
            f = b.read()
            q0 = f.q[0]
            for _ in range(5):
                b.write({"J00": q0})
                f = b.read()
            b.set_hold(True)
            seqs = []
            for _ in range(30):
                b.write({"J00": q0 + 0.05})
                f = b.read()
                seqs.append(f.seq)
            st = b.status()
            assert abs(f.q[0] - q0) < 1e-3 and b.robot_state == "holding"
            b.set_hold(False)
            for _ in range(3):
                b.write({"J00": q0})
                f = b.read()
            st2 = b.status()
    assert np.diff(seqs).tolist() == [1] * 29  # one step per command, none of the robot's own
    assert st["state"] == "HOLDING" and st["hold_commanded"] and st["hold_commands"] == 30, st
    assert st2["state"] == "RUNNING" and not st2["hold_commanded"] and st2["holds"] == 1, st2


def test_realtime_pending_command_holds_from_the_oldest_hold_commands_frame():
    """A controller that fell behind sends the hold commands of frames 7..9 in one tick: the newest is applied, the
    hold starts from frame 7; a command older than the pending one is stale."""
    from servotau.hal.robot.gate import PendingCommand

    p, q = PendingCommand(), np.zeros(3)
    assert p.take() is None
    assert p.offer(q, 0.1, 5, False)
    assert p.take()[2:] == (5, False, 5)
    for seq in (8, 7, 9):
        p.offer(q, 0.2, seq, True)
    assert p.take()[2:] == (9, True, 7) and p.take() is None
    assert p.offer(q, 0.3, 12, False) and not p.offer(q, 0.3, 11, False)
