"""In-process backend: deterministic, firmware safety in robot time, lock-step semantics."""

from __future__ import annotations

import numpy as np
from support.controller import run

from servotau.hal import InProcessBackend, LogReader, SafetyConfig
from servotau.simrobot.fake import FakeRobot


def test_same_seed_same_log(tmp_path):
    """Two in-process runs with the same seed give identical robot-side logs."""
    logs = []
    for tag in "ab":
        path = tmp_path / f"{tag}.parquet"
        with InProcessBackend(FakeRobot(seed=4), log=str(path)) as b:
            run(b, 500)
        logs.append(LogReader(path).columns)
    for k in logs[0]:
        np.testing.assert_array_equal(logs[0][k], logs[1][k], err_msg=k)


def test_watchdog_counts_robot_time():
    """Reading without writing steps with no fresh command: hold after hold_after, off after servo_off_after
    (when set: by default the robot holds indefinitely, tests/test_hal_robot_firmware.py)."""
    robot = FakeRobot()
    b = InProcessBackend(robot, SafetyConfig(hold_after=0.01, servo_off_after=0.05))
    f = b.read()
    b.write({"J00": f.q[0] + 0.05})
    for _ in range(11):
        b.read()
    assert b.robot_state == "running"
    f_hold = b.read()
    assert b.robot_state == "holding"
    for _ in range(60):
        f = b.read()
    assert b.robot_state == "servo_off" and b.status()["holds"] == 1
    assert np.abs(f.q - f_hold.q).max() < 0.01


def test_second_write_for_a_frame_is_a_rejected_replay():
    """The first command answering a frame wins; another one for the same frame is rejected as a replay, an
    older one is stale (as over Zenoh)."""
    b = InProcessBackend(FakeRobot())
    f = b.read()
    b.write({"J00": f.q[0] + 0.001})
    b.write({"J00": f.q[0] + 0.002})
    g = b.read()
    st = b.status()
    assert g.seq == f.seq + 1 and st["commands_accepted"] == 1
    assert st["commands_rejected"] == 1 and st["rejected"]["replay"] == 1 and st["commands_stale"] == 0


def test_the_truth_asked_before_a_step_is_the_one_logged_and_computed_once(tmp_path):
    """A collection asks for each tick's ground truth, then writes: the log holds that same truth, and the robot
    computes it once per tick (it was computed twice, about 7 % of a simulated collection's time)."""
    robot = FakeRobot(seed=1)
    calls = []
    truth_of = robot.ground_truth
    robot.ground_truth = lambda: calls.append(robot.read().seq) or truth_of()
    path = tmp_path / "log.parquet"
    asked = []
    with InProcessBackend(robot, log=str(path)) as b:
        for _ in range(50):
            f = b.read()
            asked.append(b.ground_truth())
            b.write({"J00": f.q[0]})
    assert calls == list(range(50))
    np.testing.assert_array_equal(LogReader(path).joints("true/q"), np.array([t.q for t in asked]))
