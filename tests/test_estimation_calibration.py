"""Tests of the sensor calibration and end-effector identification (estimation/calibration.py)."""

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from servotau.config import CONFIG_DIR
from servotau.errors import EstimationError
from servotau.estimation.calibration import (
    FtOffsetAverage,
    calibrate_ft_offsets,
    calibrate_gyro_bias,
    identify_payload,
    payload_samples,
)
from servotau.estimation.config import EstimatorConfig
from servotau.estimation.estimator import TorqueEstimator
from servotau.simrobot.scenario import Scenario
from servotau.simrobot.sim import SimConfig, SimRobot

LEG = ("RLEG_JOINT2", "RLEG_JOINT3", "RLEG_JOINT4", "RLEG_JOINT1", "RLEG_JOINT5")  # hip, knee, ankle pitch, rolls
ARM = ("RARM_JOINT0", "RARM_JOINT1", "RARM_JOINT3", "RARM_JOINT4", "RARM_JOINT5")  # shoulder, elbow, wrist
LEG_POSES = [(-1.2, 0.3, -0.8, 0.0, 0.3), (-0.3, 1.8, 0.6, -0.4, -0.3), (0.5, 0.5, -1.0, 0.25, 0.2),
             (-1.8, 1.2, 0.5, -0.2, -0.3)]
ARM_POSES = [(-1.5, -0.3, -1.0, 1.0, 0.8), (0.8, -1.2, -0.5, -1.2, -1.0), (-2.8, -0.2, -1.5, 0.3, 1.2),
             (-0.5, -0.8, -2.0, 1.5, -0.5)]


def hanging_robot() -> SimRobot:
    """Hanging, with more base damping than the default scenario so that the robot rocks less."""
    scenario = replace(Scenario.from_toml(CONFIG_DIR / "scenarios" / "hanging.toml"), base_damping=50.0)
    return SimRobot(SimConfig(scenario=scenario))


@pytest.fixture(scope="module")
def poses():
    """Hanging robot holding its right leg and arm in 5 configurations (0.4 s moves, 0.5 s holds)."""
    robot = hanging_robot()
    ix = robot.info.joint_index
    q0 = robot.read().q.copy()
    targets = [q0.copy()]
    for leg, arm in zip(LEG_POSES, ARM_POSES, strict=True):
        q = q0.copy()
        q[[ix(j) for j in LEG]] = leg
        q[[ix(j) for j in ARM]] = arm
        targets.append(q)
    frames = []
    for q in targets:
        start = robot.read().q.copy()
        for k in range(900):
            s = min(1.0, k / 400)
            robot.step(start + (q - start) * 0.5 * (1 - np.cos(np.pi * s)))
            frames.append(robot.read())
    return robot, frames


def test_ft_offsets_are_removed_by_calibration():
    """Hanging still: the offsets calibrated on 1 s match the simulator's, and remove the free-end wrench."""
    robot = hanging_robot()
    q0 = robot.read().q.copy()
    frames = []
    for _ in range(1600):
        robot.step(q0)
        frames.append(robot.read())
    true = robot.sensors.ft_offsets
    raw = TorqueEstimator(robot.info, EstimatorConfig())
    for f in frames[1000:]:
        e = raw.update(f)
    assert np.abs(e.wrenches[:, :3]).max() > 1.0
    assert np.allclose(e.wrenches, true, atol=0.3)
    offsets = calibrate_ft_offsets(frames[:1000], robot.info, EstimatorConfig())
    assert np.allclose(offsets[:, :3], true[:, :3], atol=0.15) and np.allclose(offsets[:, 3:], true[:, 3:], atol=0.015)
    est = TorqueEstimator(robot.info, EstimatorConfig().with_calibration(ft_offsets=offsets))
    for f in frames[1000:]:
        e = est.update(f)
    assert np.abs(e.wrenches[:, :3]).max() < 0.3 and np.abs(e.wrenches[:, 3:]).max() < 0.03


def test_calibrating_only_some_sensors_keeps_the_other_offsets():
    """Rows of sensors not listed keep the config's offsets."""
    robot = hanging_robot()
    frames = []
    for _ in range(200):
        robot.step(robot.read().q)
        frames.append(robot.read())
    config = EstimatorConfig().with_calibration(ft_offsets=np.full((4, 6), 7.0))
    offsets = calibrate_ft_offsets(frames, robot.info, config, sensors=["left_wrist"])
    assert np.all(offsets[:3] == 7.0) and np.abs(offsets[3]).max() < 5.0
    with pytest.raises(EstimationError, match="no valid estimate"):
        calibrate_ft_offsets(frames[:50], robot.info, config)


def test_offsets_averaged_tick_by_tick_from_a_running_estimator_equal_the_second_pass():
    """FtOffsetAverage on the estimates of an estimator using other offsets (as the control loop's settle phase)
    gives calibrate_ft_offsets's offsets on the same frames, and the same error without enough of them."""
    robot = hanging_robot()
    frames = []
    for k in range(300):
        robot.step(robot.read().q + 0.02 * np.sin(k / 40))  # moving: the compensation is not trivial
        frames.append(robot.read())
    config = EstimatorConfig().with_calibration(ft_offsets=np.random.default_rng(3).normal(0.0, 5.0, (4, 6)))
    running = TorqueEstimator(robot.info, config)
    average = FtOffsetAverage(robot.info, running.ft_offsets)
    for f in frames:
        average.add(running.update(f))
    np.testing.assert_allclose(average.offsets(config), calibrate_ft_offsets(frames, robot.info, config), atol=1e-9)
    some = average.offsets(config, sensors=["left_wrist"])
    assert np.all(some[:3] == config.ft_offsets[:3])
    short = FtOffsetAverage(robot.info, running.ft_offsets)
    with pytest.raises(EstimationError, match='"right_ankle": no valid estimate'):
        short.offsets(config)


def test_gyro_bias_is_the_mean_reading_at_rest():
    """Standing still: the calibrated gyro bias matches the simulated bias within 2e-4 rad/s."""
    robot = SimRobot(SimConfig.named("standing"))
    frames = []
    q0 = robot.read().q.copy()
    for _ in range(1500):
        robot.step(q0)
        frames.append(robot.read())
    bias = calibrate_gyro_bias(frames[1000:])  # after the first second of settling on the floor
    assert np.allclose(bias, robot.config.sensors.gyro_bias, atol=2e-4)


def test_foot_mass_and_com_are_identified_from_ft_data(poses):
    """Slow leg poses identify the foot beyond the ankle sensor (1 kg, model CoM) and the sensor offset."""
    robot, frames = poses
    v, a, w, known = payload_samples(frames, robot.info, "right_ankle", EstimatorConfig())
    assert not known.any()  # no joint beyond the ankle sensor
    p = identify_payload(a, w, v, known)
    assert p.mass == pytest.approx(1.0, rel=0.02)
    assert np.allclose(p.com, [0.0496, -0.0243, -0.01], atol=3e-3)
    true = robot.sensors.ft_offsets[0]
    assert np.allclose(p.offset[:3], true[:3], atol=0.1) and np.allclose(p.offset[3:], true[3:], atol=0.01)


def test_hand_mass_and_com_are_identified_with_the_gripper_known(poses):
    """With the gripper modelled as known, slow arm poses identify the hand (0.4 kg, model CoM)."""
    robot, frames = poses
    v, a, w, known = payload_samples(frames, robot.info, "right_wrist", EstimatorConfig())
    assert np.abs(known).max() > 0.5  # the 0.2 kg gripper
    p = identify_payload(a, w, v, known)
    assert p.mass == pytest.approx(0.4, rel=0.02)
    assert np.allclose(p.com, [0.0, 0.0, -0.04], atol=3e-3)


def test_inertia_is_identified_from_exact_dynamic_data():
    """Synthetic exact wrenches of a rotating body give back its mass, CoM, inertia and offset."""
    rng = np.random.default_rng(0)
    body = pin.Inertia(0.7, np.array([0.01, -0.02, -0.05]), np.diag([2e-3, 3e-3, 1.5e-3]))
    offset = rng.standard_normal(6)
    v = rng.standard_normal((60, 6))
    a = rng.standard_normal((60, 6)) + np.array([0.0, 0.0, 9.81, 0.0, 0.0, 0.0])
    w = np.array([-(body * pin.Motion(ak) + body.vxiv(pin.Motion(vk))).vector for vk, ak in zip(v, a, strict=True)])
    p = identify_payload(a, w + offset, v, inertia=True)
    assert p.mass == pytest.approx(0.7) and np.allclose(p.com, body.lever) and np.allclose(p.offset, offset)
    about_origin = body.inertia + 0.7 * (np.dot(body.lever, body.lever) * np.eye(3) - np.outer(body.lever, body.lever))
    assert np.allclose(p.inertia, about_origin)


def test_one_orientation_is_not_enough():
    """Static samples in a single orientation cannot separate the CoM from the offset: EstimationError."""
    s = np.tile([0.0, 0.0, 9.81], (50, 1))
    w = np.tile([0.0, 0.0, -9.81, 0.1, 0.0, 0.0], (50, 1))
    with pytest.raises(EstimationError, match="excite"):
        identify_payload(s, w)
