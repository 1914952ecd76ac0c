"""Backend conformance: zenoh (robot in a subprocess), inprocess and replay behave the same way."""

from __future__ import annotations

import math

import numpy as np
import pytest

from servotau.errors import HalError
from servotau.hal import Backend, InProcessBackend, LogWriter, ReplayBackend, ZenohBackend
from servotau.simrobot.fake import FakeRobot

LIVE = ("zenoh", "inprocess")


@pytest.fixture(params=["zenoh", "inprocess", "replay"])
def backend(request, tmp_path):
    """An open backend on a FakeRobot(seed=0), closed after the test."""
    kind = request.param
    if kind == "zenoh":
        b = request.getfixturevalue("fake_zenoh")  # tests/conftest.py
        b.kind = kind
        yield b
        return
    if kind == "inprocess":
        b = InProcessBackend(FakeRobot(seed=0))
    else:
        path = tmp_path / "recorded.parquet"
        with InProcessBackend(FakeRobot(seed=0)) as src, LogWriter(path, src.info) as w:
            for k in range(400):
                f, truth = src.read(), src.ground_truth()
                src.write({"J00": f.q[0] + 0.01 * np.sin(k / 50)})
                w.append(f, src.q_des, truth)
        b = ReplayBackend(path)
    b.kind = kind
    with b:
        yield b


def _robot_status(b: Backend) -> dict:
    return b.status() if b.kind in LIVE else {}


def test_read_returns_valid_frames_in_order(backend):
    """Frames have the robot's shapes, finite values, seq +1 per tick and increasing robot time."""
    nq = backend.info.nq
    prev = None
    for _ in range(100):
        f = backend.read()
        assert f.q.shape == (nq,) and f.wrenches.shape == (4, 6) and f.status.shape == (6,)
        assert f.imu_angular_velocity.shape == (3,) and f.imu_linear_acceleration.shape == (3,)
        assert np.isfinite(f.q).all() and f.all_ok
        if prev is not None:
            assert f.seq == prev.seq + 1 and f.time > prev.time
            assert math.isclose(f.time - prev.time, backend.info.period)
        backend.write({})
        prev = f
    assert backend.last_frame is f


def test_write_by_name(backend):
    """Named joints get the new angle, the others keep theirs (initially the first measured position)."""
    f0 = backend.read()
    np.testing.assert_array_equal(backend.q_des, f0.q)
    target = f0.q[3] + 0.05
    backend.write({"J03": target})
    expected = f0.q.copy()
    expected[3] = target
    np.testing.assert_array_equal(backend.q_des, expected)
    for _ in range(150):
        backend.read()
        backend.write({"J05": f0.q[5]})
    f = backend.read()  # lock-step: the robot has taken every command
    if backend.kind in LIVE:
        assert abs(f.q[3] - target) < 0.01  # first-order servo, 20 ms time constant
        assert np.abs(np.delete(f.q - f0.q, 3)).max() < 0.01
        assert _robot_status(backend)["commands_accepted"] == 151
    else:
        seq, q = backend.commands_array()
        assert len(seq) == 151 and (q[:, 3] == target).all() and seq[0] == f0.seq


@pytest.mark.parametrize("bad, match", [
    ({"NOPE": 0.1}, 'joint "NOPE" is not a joint of fake: expected one of'),
    ({"J01": 0.1, "J02": float("nan")}, r'q_des\["J02"\] = nan: expected a finite angle \[rad\]'),
    ({"J02": float("inf")}, r'q_des\["J02"\] = inf'),
    ({"J02": "zero"}, r"q_des\[\"J02\"\] = 'zero'"),
    ([0.1, 0.2], "expected a mapping joint name -> angle"),
])
def test_bad_writes_are_rejected_and_nothing_is_sent(backend, bad, match):
    """Unknown joints, NaN, inf, non-numbers: HalError naming the joint; nothing sent, nothing applied."""
    backend.read()
    before = backend.q_des
    accepted = _robot_status(backend).get("commands_accepted")
    with pytest.raises(HalError, match=match):
        backend.write(bad)
    with pytest.raises(HalError, match="expected"):
        backend.write_array(np.full(backend.info.nq, np.nan))
    np.testing.assert_array_equal(backend.q_des, before)
    assert backend.commands_sent == 0
    if backend.kind in LIVE:
        assert _robot_status(backend)["commands_accepted"] == accepted
    else:
        assert backend.commands == []


def test_info_is_consistent(backend):
    """RobotInfo matches the frames and the served robot."""
    info, ref = backend.info, FakeRobot().info
    f = backend.read()
    assert info.joint_names == ref.joint_names and info.nq == len(f.q) == 30
    np.testing.assert_array_equal(info.q_min, ref.q_min)
    np.testing.assert_array_equal(info.q_max, ref.q_max)
    assert info.period == ref.period and info.joint_index("J07") == 7
    assert info.ft_sensor_names == ref.ft_sensor_names and info.max_position_error == ref.max_position_error


def _truth(backend: Backend):
    """The ground truth of the last frame read; over zenoh it comes after the frame: wait for it up to 5 s (the
    backend's default of 5 ms is for a control loop, which goes on without it)."""
    return backend.ground_truth(wait=5.0) if isinstance(backend, ZenohBackend) else backend.ground_truth()


def test_write_array_and_ground_truth(backend):
    """write_array is the vector fast path; ground truth (sim) is that of the last frame read."""
    f = backend.read()
    backend.write_array(f.q + 0.001)
    np.testing.assert_array_equal(backend.q_des, f.q + 0.001)
    with pytest.raises(HalError, match=r"shape \(3,\): expected \(30,\)"):
        backend.write_array(np.zeros(3))
    for _ in range(3):
        f = backend.read()
        t = _truth(backend)
        assert t is not None and t.q.shape == (30,) and t.seq == f.seq
        backend.write({})
        assert _truth(backend).seq == f.seq  # still the tick of the frame read, after the write


def test_closed_backend_refuses_io(backend):
    """After close(), write raises HalError (close is idempotent)."""
    backend.read()
    backend.close()
    backend.close()
    with pytest.raises(HalError, match="closed"):
        backend.write({})
