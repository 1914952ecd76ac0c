"""Parquet log: round trip, schema, extras, crash safety."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from support.hal import ENV

from servotau.errors import HalError
from servotau.hal import LogReader, LogWriter, frames, read_log
from servotau.hal.log import parts_dir
from servotau.simrobot.fake import FakeRobot


def _record(path, n=250, **kw):
    robot = FakeRobot(seed=5)
    rows = []
    with LogWriter(path, robot.info, chunk_rows=100, **kw) as w:
        for k in range(n):
            f, t = robot.read(), robot.ground_truth()
            q_des = f.q + 0.01
            w.append(f, q_des, t, {"est/tau": np.full(robot.info.nq, float(k)), "est/ok": 1.0})
            rows.append((f, q_des, t))
            robot.step(q_des)
    return robot.info, rows


def test_write_read_round_trip(tmp_path):
    """Frames, q_des, ground truth and extras come back exactly, RobotInfo from the metadata."""
    path = tmp_path / "run.parquet"
    info, rows = _record(path)
    assert not parts_dir(path).exists()
    info2, cols = read_log(path)
    assert info2.joint_names == info.joint_names and info2.period == info.period
    assert len(cols["t"]) == len(rows) and cols["seq"].dtype == np.int64
    assert cols["status/encoders"].dtype == np.uint8
    log = LogReader(path)
    for (f, _, _), g in zip(rows, frames(log), strict=True):
        assert (g.seq, g.time) == (f.seq, f.time)
        for name in ("q", "imu_angular_velocity", "imu_linear_acceleration", "wrenches", "status"):
            np.testing.assert_array_equal(getattr(g, name), getattr(f, name))
    np.testing.assert_array_equal(log.joints("q_des"), np.array([r[1] for r in rows]))
    np.testing.assert_array_equal(log.joints("true/q"), np.array([r[2].q for r in rows]))
    np.testing.assert_array_equal(log.truth(7).to_vector(), rows[7][2].to_vector())
    np.testing.assert_array_equal(cols["est/tau/J03"], np.arange(len(rows), dtype=float))
    assert "ft/left_ankle/fz" in cols and "imu/acc_z" in cols and "true/base_position/z" in cols
    assert log.metadata["servotau.log_format"] == "1"


def test_no_truth_and_undeclared_extra(tmp_path):
    """Without ground truth there is no true/ column; an extra not in the first row is refused."""
    robot = FakeRobot()
    with LogWriter(tmp_path / "a.parquet", robot.info) as w:
        w.append(robot.read(), None, None, {"x": 1.0})
        with pytest.raises(HalError, match='"y" was not declared'):
            w.append(robot.read(), None, None, {"y": 1.0})
    log = LogReader(tmp_path / "a.parquet")
    assert not any(c.startswith("true/") for c in log.columns) and not log.has_truth
    assert np.isnan(log.columns["q_des/J00"][0])


def test_error_inside_with_keeps_rows(tmp_path):
    """An exception in the recording loop still leaves a complete, readable log."""
    robot = FakeRobot()
    path = tmp_path / "b.parquet"
    with pytest.raises(RuntimeError), LogWriter(path, robot.info, chunk_rows=64) as w:
        for _ in range(150):
            w.append(robot.read())
            robot.step(robot.read().q)
        raise RuntimeError("controller bug")
    assert len(LogReader(path)) == 150


def test_crash_loses_at_most_the_last_chunk(tmp_path):
    """A process killed without closing its log leaves every completed chunk readable."""
    path = tmp_path / "crash.parquet"
    code = f"""
import os
from servotau.simrobot.fake import FakeRobot
from servotau.hal import LogWriter
robot = FakeRobot()
w = LogWriter({str(path)!r}, robot.info, chunk_rows=100, background=False)
for _ in range(250):
    w.append(robot.read())
    robot.step(robot.read().q)
os._exit(1)
"""
    assert subprocess.run([sys.executable, "-c", code], env=ENV, timeout=60).returncode == 1
    assert not path.exists() and parts_dir(path).exists()
    log = LogReader(path)
    assert len(log) == 200 and list(log.columns["seq"][:3]) == [0, 1, 2]
