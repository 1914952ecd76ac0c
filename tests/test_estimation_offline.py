"""Tests of off-line estimation (estimation/offline.py): replay of recorded frames and the non-causal estimator."""

import numpy as np
import pytest

from servotau.errors import EstimationError
from servotau.estimation.config import EstimatorConfig
from servotau.estimation.estimator import Estimate, TorqueEstimator
from servotau.estimation.offline import estimate_offline, frames_to_arrays, replay
from servotau.simrobot.sim import SimConfig, SimRobot


def ramp(s: float) -> float:
    return 0.0 if s <= 0.0 else 1.0 if s >= 1.0 else 0.5 * (1.0 - np.cos(np.pi * s))


@pytest.fixture(scope="module")
def swing():
    """Hanging robot swinging its right leg for 2.5 s with the on-line estimator in the loop."""
    robot = SimRobot(SimConfig.named("hanging"))
    config = EstimatorConfig().with_calibration(ft_offsets=robot.sensors.ft_offsets)
    est = TorqueEstimator(robot.info, config)
    q0 = robot.read().q.copy()
    frames, truths, online = [], [], []
    for _ in range(2500):
        s = robot.time - 0.3
        q = q0.copy()
        q[0:6] += ramp(s) * np.array([0.15, -0.25, 0.4, 0.5, -0.3, -0.15]) * np.sin(
            2 * np.pi * np.array([0.5, 0.7, 0.35, 0.6, 0.8, 0.9]) * s)
        robot.step(q)
        frames.append(robot.read())
        truths.append(robot.ground_truth())
        online.append(est.update(frames[-1]).copy())
    return robot, config, frames, truths, online


def test_replayed_estimates_are_bit_identical_to_the_online_run(swing):
    """Feeding the recorded frames to a fresh estimator reproduces every on-line output bit for bit."""
    robot, config, frames, _, online = swing
    replayed = replay(frames, robot.info, config)
    assert len(replayed) == len(online)
    for a, b in zip(online, replayed, strict=True):
        for name in Estimate._ARRAYS:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        for name in Estimate._SCALARS:
            x, y = getattr(a, name), getattr(b, name)
            assert x == y or (np.isnan(x) and np.isnan(y))


def test_offline_estimate_is_aligned_with_the_samples_and_accurate(swing):
    """The non-causal estimate is aligned with the samples and at least as accurate as the on-line one."""
    robot, config, frames, truths, online = swing
    a = frames_to_arrays(frames)
    off = estimate_offline(a["time"], a["q"], a["imu_angular_velocity"], a["imu_linear_acceleration"],
                           a["wrenches"], robot.info, config, a["status"])
    assert off.q.shape == (len(frames), robot.info.nq) and off.wrenches.shape == (len(frames), 4, 6)
    true_q = np.array([t.q for t in truths])
    true_tau = np.array([t.tau for t in truths])
    times = np.array([t.time for t in truths])
    keep = off.valid & (times > 1.0)
    assert not off.valid[:40].any() and not off.valid[-40:].any()  # half a window at both ends
    assert np.abs(off.q[keep] - true_q[keep]).max() < 1e-3
    off_rms = np.sqrt(np.mean((off.tau[keep] - true_tau[keep])[:, 0:6] ** 2, axis=0))
    on = [e for e in online if e.valid and e.time > 1.0]
    on_err = np.array([e.tau[0:6] - [np.interp(e.time, times, true_tau[:, j]) for j in range(6)] for e in on])
    on_rms = np.sqrt(np.mean(on_err**2, axis=0))
    assert np.all(off_rms <= on_rms * 1.05) and np.all(off_rms < 0.7), (off_rms, on_rms)


def test_offline_bad_samples_are_flagged_not_filtered(swing):
    """A NaN left-knee sample flags the left-leg and chest torques within half a window, nothing else."""
    robot, config, frames, _, _ = swing
    a = frames_to_arrays(frames)
    knee = robot.info.joint_index("LLEG_JOINT3")
    a["q"][1000, knee] = np.nan
    off = estimate_offline(a["time"], a["q"], a["imu_angular_velocity"], a["imu_linear_acceleration"],
                           a["wrenches"], robot.info, config, a["status"])
    assert np.isnan(off.tau[960:1041, 6:12]).all() and np.isnan(off.tau[1000, 12:14]).all()
    assert np.isfinite(off.tau[960:1041, 0:6]).all() and np.isfinite(off.tau[1000, 14:]).all()
    assert np.isfinite(off.tau[959, 6:12]).all() and np.isfinite(off.tau[1041, 6:12]).all()
    assert not off.valid[1000] and off.valid[1100]


def test_offline_rejects_non_uniform_time(swing):
    """A gap in the time stamps raises EstimationError (the filters assume uniform sampling)."""
    robot, config, frames, _, _ = swing
    a = frames_to_arrays(frames[:300])
    a["time"][150:] += 0.01
    with pytest.raises(EstimationError, match="uniform"):
        estimate_offline(a["time"], a["q"], a["imu_angular_velocity"], a["imu_linear_acceleration"],
                         a["wrenches"], robot.info, config)


def test_estimates_replayed_from_a_parquet_log_are_bit_identical(swing, tmp_path):
    """Frames written to the project's Parquet log and played by ReplayBackend give the on-line estimates."""
    log = pytest.importorskip("servotau.hal.log")
    replay_backend = pytest.importorskip("servotau.hal.backends.replay")
    robot, config, frames, truths, online = swing
    path = tmp_path / "swing.parquet"
    with log.LogWriter(path, robot.info, truth=False, extra=[], background=False) as writer:
        for f in frames[:600]:
            writer.append(f)
    backend = replay_backend.ReplayBackend(path)
    est = TorqueEstimator(backend.info, config)
    for k in range(600):
        e = est.update(backend.read())
        np.testing.assert_array_equal(e.tau, online[k].tau)
        np.testing.assert_array_equal(e.wrenches, online[k].wrenches)
        assert e.time == online[k].time and e.valid == online[k].valid
