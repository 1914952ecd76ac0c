"""Replay backend: reproduces a recorded log exactly, records commands, ends with EndOfLog."""

from __future__ import annotations

import numpy as np
import pytest

from servotau.errors import HalError
from servotau.hal import EndOfLog, InProcessBackend, LogWriter, ReplayBackend
from servotau.simrobot.fake import FakeRobot


def _record(path, n=300):
    recorded = []
    with InProcessBackend(FakeRobot(seed=11)) as b, LogWriter(path, b.info) as w:
        for k in range(n):
            f, t = b.read(), b.ground_truth()
            b.write({"J10": f.q[10] + 0.02 * np.sin(k / 30)})
            w.append(f, b.q_des, t, {"est/k": float(k)})
            recorded.append((f, t))
    return recorded


def test_replay_reproduces_recorded_frames_exactly(tmp_path):
    """Every frame read back equals the recorded one (arrays, seq, time), truth included; then EndOfLog."""
    path = tmp_path / "rec.parquet"
    recorded = _record(path)
    with ReplayBackend(path) as rb:
        assert len(rb) == len(recorded)
        for f, t in recorded:
            g = rb.read()
            assert (g.seq, g.time) == (f.seq, f.time)
            for name in ("q", "imu_angular_velocity", "imu_linear_acceleration", "wrenches", "status"):
                np.testing.assert_array_equal(getattr(g, name), getattr(f, name))
            np.testing.assert_array_equal(rb.ground_truth().to_vector(), t.to_vector())
            rb.write({"J01": 0.5})
        with pytest.raises(EndOfLog, match="end of log after 300 frames"):
            rb.read()
        seq, q = rb.commands_array()
        np.testing.assert_array_equal(seq, [f.seq for f, _ in recorded])
        assert (q[:, 1] == 0.5).all() and q.shape == (300, 30)
    assert issubclass(EndOfLog, HalError) and issubclass(EndOfLog, EOFError)


def test_replay_of_missing_log_is_a_hal_error(tmp_path):
    """A missing file raises HalError naming the path."""
    with pytest.raises(HalError, match="nope.parquet"):
        ReplayBackend(tmp_path / "nope.parquet")
