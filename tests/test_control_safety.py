"""Tests of servotau.control.safety: every check trips, latches a hold of the measured position, names itself."""

import dataclasses

import numpy as np
import pytest

from servotau.control import ControlConfig, ControlManager, Mode, StateEstimate
from servotau.control.safety import CHECKS, SafetyMonitor
from servotau.control.trajectory import TrajectoryPoint
from servotau.description import JOINT_NAMES
from servotau.errors import ControlError, SafetyTrip
from servotau.estimation import EstimatorConfig, TorqueEstimator
from servotau.hal.types import STATUS_SATURATED, SensorFrame
from servotau.simrobot.model import default_joint_map, half_sitting_qpos
from servotau.simrobot.sim import SimConfig, SimRobot

ROBOT = SimRobot(SimConfig.named("hanging"))
INFO = ROBOT.info
KNEE = JOINT_NAMES.index("RLEG_JOINT3")
ARM = JOINT_NAMES.index("LARM_JOINT0")
Q0 = half_sitting_qpos()[default_joint_map().mj_qpos]


def _frame(k, q=None, status=None, time=None):
    return SensorFrame(time=k * 1e-3 if time is None else time, seq=k, q=Q0.copy() if q is None else q,
                       imu_angular_velocity=np.zeros(3), imu_linear_acceleration=np.array([0, 0, 9.81]),
                       wrenches=np.zeros((4, 6)), status=np.zeros(6, np.uint8) if status is None else status)


def _estimate(q=None):
    return StateEstimate(Q0.copy() if q is None else q, np.zeros(30), np.zeros(30), np.zeros(30), np.zeros((4, 6)))


def _ref(offset=0.0):
    return TrajectoryPoint(Q0 + offset, np.zeros(30), np.zeros(30))


def _fault(check):
    """(frame, estimate, reference) of the faulty tick k = 10 for ``check``, and the expected joint or sensor."""
    k, q = 10, Q0.copy()
    if check == "robot_servo_off":  # the backend's robot_state, passed to the tick
        return _frame(k), _estimate(), _ref(), "robot"
    if check == "sensor_status":
        status = np.zeros(6, np.uint8)
        status[2] = STATUS_SATURATED
        return _frame(k, status=status), _estimate(), _ref(), "right_ankle"
    if check == "stale_frame":
        return _frame(k, time=9e-3), _estimate(), _ref(), ""
    if check == "invalid_frame":
        q[KNEE] = np.nan
        return _frame(k, q=q), _estimate(), _ref(), "RLEG_JOINT3"
    if check == "joint_limit":
        q[KNEE] = INFO.q_max[KNEE] - 0.01  # inside the range, inside the 0.02 rad margin
        return _frame(k, q=q), _estimate(q), _ref(), "RLEG_JOINT3"
    est = _estimate()
    if check == "invalid_estimate":
        est.ddq[KNEE] = np.nan
    elif check == "estimate_gap":  # the estimator after a gap longer than its max_gap: finite but invalid
        est.valid, est.gap_flush = False, 80
        return _frame(k), est, _ref(), ""
    elif check == "joint_velocity":
        est.dq[KNEE] = -6.0
    elif check == "joint_torque":
        est.tau[KNEE] = 400.0
    elif check == "command_error":
        ref = _ref()
        ref.q[ARM] += 0.2  # a reference jump on a position-controlled joint
        return _frame(k), est, ref, "LARM_JOINT0"
    return _frame(k), est, _ref(), "RLEG_JOINT3"


def test_an_encoder_glitch_brakes_the_hold_by_at_most_hold_damping_times_max_velocity():
    """The joint-limit fault (the knee's reading jumps 1.7 rad in a tick): the braking term of the hold stays
    within hold_damping * max_velocity of the measured angles, and is gone after hold_brake_time."""
    mgr = ControlManager.from_toml(INFO)
    s = mgr.config.safety
    for k in range(10):
        mgr.tick(_frame(k), _estimate(), _ref())
    frame, est, ref, _ = _fault("joint_limit")
    out = mgr.tick(frame, est, ref)
    assert mgr.report.check == "joint_limit"
    brake = np.abs(out.q_des - frame.q)
    assert brake.max() > 0 and np.all(brake <= s.hold_damping * s.max_velocity + 1e-12)
    for k in range(11, 11 + round(s.hold_brake_time / INFO.period) + 1):
        out = mgr.tick(_frame(k), _estimate(), _ref())
    np.testing.assert_array_equal(out.q_des, frame.q)


@pytest.mark.parametrize("check", [*CHECKS, None])
def test_each_check_trips_and_latches_a_hold(check):
    """A fault trips the named check (joint, value vs limit); the hold keeps the measured angles until reset()."""
    config = ControlManager.from_toml(INFO).config
    config = dataclasses.replace(config, safety=dataclasses.replace(config.safety, hold_damping=0.0))  # no braking
    if check == "estimate_gap":  # the default falls back to position control instead
        config = dataclasses.replace(config, gap_fallback="trip")
    mgr = ControlManager(INFO, config)
    mgr.request_mode("torque")
    for k in range(10):
        mgr.tick(_frame(k), _estimate(), _ref())
    assert mgr.mode == Mode.TORQUE and not mgr.tripped
    if check is None:  # control: the same ticks without a fault do not trip
        frame, est, ref, where = _frame(10), _estimate(), _ref(), None
    else:
        frame, est, ref, where = _fault(check)
    out = mgr.tick(frame, est, ref, check == "robot_servo_off")
    if check is None:
        assert not mgr.tripped and out.mode == "torque"
        return
    assert mgr.tripped and out.mode == "hold" and out.tripped
    r = mgr.report
    assert (r.check, r.where, r.seq) == (check, where, 10)
    assert check in r.message and (where or "") in r.message
    assert isinstance(r.error(), SafetyTrip)
    held = np.where(np.isfinite(frame.q), frame.q, Q0)  # measured angles (last good one where NaN)
    np.testing.assert_array_equal(out.q_des, held)
    for k in range(11, 20):  # good frames, a moving reference: still holding the same angles
        out = mgr.tick(_frame(k), _estimate(), _ref(0.05 * (k - 10)))
        np.testing.assert_array_equal(out.q_des, held)
        assert mgr.mode == Mode.HOLD
    with pytest.raises(ControlError, match="reset"):
        mgr.request_mode("torque")
    mgr.reset()
    out = mgr.tick(_frame(20, q=held.copy()), _estimate(held.copy()), _ref())
    if check == "joint_limit":  # still beyond the margin: trips again at once
        assert mgr.tripped and mgr.report.check == "joint_limit"
        return
    assert mgr.mode == Mode.POSITION and not mgr.tripped
    np.testing.assert_allclose(out.q_des, held, atol=1e-12)  # faded from the held angles, no jump


def test_monitor_reports_value_and_limit():
    """The report carries the offending value and the limit: |tau_hat| 400 N m against 300 N m."""
    mon = SafetyMonitor(INFO, ControlConfig.from_toml("control.toml", INFO).safety)
    est = _estimate()
    est.tau[KNEE] = -400.0
    r = mon.check_estimate(_frame(1), est.q, est.dq, est.ddq, est.tau)
    assert (r.check, r.where, r.value, r.limit) == ("joint_torque", "RLEG_JOINT3", -400.0, 300.0)
    assert "400" in r.message and "300" in r.message


def test_trip_in_simulation_holds_the_robot_still():
    """In simulation a trip in torque mode holds the legs within 5 mrad of the trip angles as the reference moves."""
    robot = ROBOT.with_seed(1)
    est = TorqueEstimator(INFO, EstimatorConfig.from_toml(variant="low_delay"))
    mgr = ControlManager.from_toml(INFO)
    frame = robot.read()
    q0 = frame.q.copy()
    trip_at, q_trip = 400, None
    for k in range(1000):
        e = est.update(frame)
        if k == 100:
            mgr.request_mode("torque")
        if k == trip_at:
            frame = dataclasses.replace(frame, time=frame.time - 1e-3)  # robot time went backwards
        ref = TrajectoryPoint(q0 + (0.0 if k < trip_at else 0.1), np.zeros(30), np.zeros(30))
        out = mgr.tick(frame, e if e.valid else None, ref)
        if k == trip_at:
            assert mgr.report.check == "stale_frame"
            q_trip = out.q_des.copy()
        robot.step(out.q_des)
        frame = robot.read()
    assert mgr.mode == Mode.HOLD
    np.testing.assert_array_equal(out.q_des, q_trip)
    drift = np.abs(robot.ground_truth().q - q_trip)
    assert drift[:12].max() < 5e-3, drift[:12]
