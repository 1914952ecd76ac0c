"""Tests of the per-tick dynamics (estimation/dynamics.py) with exact, unfiltered inputs from the simulator."""

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from servotau.estimation.config import EstimatorConfig
from servotau.estimation.dynamics import InverseDynamics, cross_into
from servotau.estimation.model import EstimatorModel
from servotau.simrobot.scenario import OperatorPush
from servotau.simrobot.sim import SimConfig, SimRobot


def exact_inputs(robot: SimRobot):
    """Noise-free q, dq, ddq, gyro, its derivative and accelerometer from MuJoCo (test-only access)."""
    m, d = robot.model, robot.data
    dof = [m.joint(j).dofadr[0] for j in robot.joint_names]
    imu = m.site("imu").id
    acc6 = np.zeros(6)
    mujoco.mj_objectAcceleration(m, d, mujoco.mjtObj.mjOBJ_SITE, imu, acc6, 1)  # [angular, linear], site frame
    gyro = d.sensordata[m.sensor("imu_gyro").adr[0]:][:3].copy()
    accel = d.sensordata[m.sensor("imu_accel").adr[0]:][:3].copy()
    return d.qvel[dof].copy(), d.qacc[dof].copy(), gyro, acc6[:3].copy(), accel


@pytest.fixture(scope="module")
def swinging():
    """Hanging robot pushed on the chest and the right hand, chest, right leg and arm moving: (truth, inputs)
    at 6 instants."""
    robot = SimRobot(SimConfig.named("hanging"))
    robot.add_push(OperatorPush("CHEST_LINK1", 0.0, 10.0, np.array([40.0, 0.0, 0.0]), np.zeros(3)))
    robot.add_push(OperatorPush("RARM_HAND", 0.0, 10.0, np.array([0.0, 12.0, -16.0]), np.zeros(3)))  # 20 N
    q0 = robot.read().q.copy()
    samples = []
    for k in range(1200):
        t = k * robot.period
        q = q0.copy()
        q[0:6] += 0.3 * np.sin(2 * np.pi * 0.8 * t) * np.array([0.5, 0.5, 1.0, 1.0, 1.0, 0.5])
        q[16:19] += 0.3 * np.sin(2 * np.pi * 0.6 * t)
        q[12] += 0.2 * np.sin(2 * np.pi * 0.4 * t)  # chest yaw and pitch: the IMU moves relative to the waist
        q[13] += 0.15 * (1 - np.cos(2 * np.pi * 0.5 * t))
        robot.step(q)
        if k >= 600 and k % 100 == 0:
            samples.append((robot.ground_truth(), *exact_inputs(robot)))
    return robot, samples


def test_exact_inputs_give_the_true_torques_and_base_motion(swinging):
    """Exact inputs give the true torques (1e-6 N m), base rate and external wrenches (20 N on the hand)."""
    robot, samples = swinging
    dyn = InverseDynamics(EstimatorModel(robot.info, EstimatorConfig()))
    chest = [robot.info.joint_index("CHEST_JOINT0"), robot.info.joint_index("CHEST_JOINT1")]
    others = [i for i in range(robot.info.nq) if i not in chest]
    for truth, dq, ddq, gyro, dgyro, accel in samples:
        dyn.compute(truth.q, dq, ddq, gyro, dgyro, accel, truth.wrenches)
        assert np.allclose(dyn.tau[others], truth.tau[others], atol=1e-6)
        # The base damping of the hanging scenario is an extra external wrench on the waist: the chest
        # joints, computed from the waist side, see it (5 N m s/rad times the base rate).
        damping = 5.0 * np.linalg.norm(truth.base_velocity[3:])  # [N m]
        assert np.allclose(dyn.tau[chest], truth.tau[chest], atol=1.05 * damping + 1e-6)
        assert np.allclose(dyn.base_angular_velocity, truth.base_velocity[3:], atol=1e-9)
        assert np.linalg.norm(dyn.wrenches[2, :3]) == pytest.approx(20.0, abs=1e-6)
        assert np.abs(dyn.wrenches[[0, 1, 3]]).max() < 1e-6


def test_strings_are_the_unknown_wrench_on_the_torso(swinging):
    """Hanging and pushed: the unknown wrench is on the torso; assigning it to the waist breaks the chest."""
    robot, samples = swinging
    mass = float(np.sum(robot.model.body_mass))
    torso = InverseDynamics(EstimatorModel(robot.info, EstimatorConfig()))
    waist = InverseDynamics(EstimatorModel(robot.info, replace(EstimatorConfig(), unknown_wrench_link="BODY")))
    chest = robot.info.joint_index("CHEST_JOINT1")
    truth, dq, ddq, gyro, dgyro, accel = samples[-1]
    for dyn in (torso, waist):
        dyn.compute(truth.q, dq, ddq, gyro, dgyro, accel, truth.wrenches)
    assert np.linalg.norm(torso.base_wrench[:3]) == pytest.approx(mass * 9.81, rel=0.1)  # strings + push
    damping = 5.0 * np.linalg.norm(truth.base_velocity[3:])  # base damping of the hanging scenario [N m]
    assert abs(torso.tau[chest] - truth.tau[chest]) < 1.05 * damping + 1e-6
    # The push (40 N x 0.165 m) and the strings' moments are missing from the waist variant.
    assert abs(waist.tau[chest] - truth.tau[chest]) > abs(torso.tau[chest] - truth.tau[chest]) + 2.0


def test_neglected_angular_acceleration_is_zero(swinging):
    """angular_acceleration="neglect" sets the base angular acceleration to 0 (and ignores dgyro)."""
    robot, samples = swinging
    cfg = replace(EstimatorConfig(), angular_acceleration="neglect")
    dyn = InverseDynamics(EstimatorModel(robot.info, cfg), cfg.angular_acceleration)
    truth, dq, ddq, gyro, dgyro, accel = samples[0]
    dyn.compute(truth.q, dq, ddq, gyro, np.full(3, 1e3), accel, truth.wrenches)
    assert not dyn.base_angular_acceleration.any()
    assert np.all(np.isfinite(dyn.tau))


def test_cross_helper_matches_numpy():
    """cross_into agrees with numpy's cross product."""
    rng = np.random.default_rng(1)
    a, b = rng.standard_normal(3), rng.standard_normal(3)
    assert np.allclose(cross_into(a, b, np.zeros(3)), np.cross(a, b))
