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
    """Reading without writing steps with no fresh command: hold after hold_after, off after servo_off_after."""
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


def test_second_write_for_a_frame_is_stale():
    """The first command answering a frame wins; later ones are counted stale (as over Zenoh)."""
    b = InProcessBackend(FakeRobot())
    f = b.read()
    b.write({"J00": f.q[0] + 0.01})
    b.write({"J00": f.q[0] + 0.02})
    g = b.read()
    assert g.seq == f.seq + 1 and b.status()["commands_stale"] == 1 and b.status()["commands_accepted"] == 1
