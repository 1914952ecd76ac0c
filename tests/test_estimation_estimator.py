"""Tests of the on-line torque estimator (estimation/estimator.py) against the simulator's ground truth."""

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from servotau.config import CONFIG_DIR
from servotau.description import load_pinocchio
from servotau.errors import EstimationError
from servotau.estimation.config import EstimatorConfig
from servotau.estimation.estimator import TorqueEstimator
from servotau.hal.types import STATUS_INVALID, STATUS_STALE, RobotInfo, SensorFrame
from servotau.simrobot.model import mujoco_to_pinocchio_state
from servotau.simrobot.scenario import Scenario
from servotau.simrobot.sim import SimConfig, SimRobot

G = 9.81  # [m/s^2]
LEG = slice(0, 12)


def record(scenario: str | Scenario, seconds: float, command=None):
    """Frames and ground truths of a lock-step run (command(t, q0) -> q_des)."""
    robot = SimRobot(SimConfig.named(scenario) if isinstance(scenario, str) else SimConfig(scenario=scenario))
    q0 = robot.read().q.copy()
    frames, truths = [], []
    for _ in range(int(round(seconds / robot.period))):
        robot.step(q0 if command is None else command(robot.time, q0))
        frames.append(robot.read())
        truths.append(robot.ground_truth())
    return robot, frames, truths


def oracle_config(robot: SimRobot) -> EstimatorConfig:
    """Default settings with the simulator's F/T offsets (the calibration is tested in its own file)."""
    return EstimatorConfig().with_calibration(ft_offsets=robot.sensors.ft_offsets)


def run(info, frames, config):
    est = TorqueEstimator(info, config)
    return est, [est.update(f).copy() for f in frames]


def truth_at(truths, t: float) -> np.ndarray:
    """True joint torques interpolated at time t [s] (the estimate's time stamp)."""
    times = np.array([x.time for x in truths])
    tau = np.array([x.tau for x in truths])
    return np.array([np.interp(t, times, tau[:, j]) for j in range(tau.shape[1])])


def ramp(s: float) -> float:
    """Smooth 0 -> 1 over the first second (no step of the commanded velocity: no torque impulse)."""
    return 0.0 if s <= 0.0 else 1.0 if s >= 1.0 else 0.5 * (1.0 - np.cos(np.pi * s))


def arm_motion(t: float, q0: np.ndarray) -> np.ndarray:
    q = q0.copy()
    s = max(0.0, t - 1.5)
    q[16] += ramp(2 * s) * 0.4 * np.sin(2 * np.pi * 0.7 * s)  # right shoulder pitch
    q[19] += -0.3 * (1 - np.cos(2 * np.pi * 0.9 * s))  # right elbow
    q[22] += ramp(2 * s) * 0.3 * np.sin(2 * np.pi * 1.1 * s)  # right gripper
    return q


@pytest.fixture(scope="module")
def standing():
    """Standing 1.5 s still, then 1.5 s moving the right arm (no contact at the hands)."""
    robot, frames, truths = record("standing", 3.0, arm_motion)
    est, estimates = run(robot.info, frames, oracle_config(robot))
    return robot, frames, truths, estimates


@pytest.fixture(scope="module")
def hanging():
    """Hanging 1.5 s still, with a strong base damping so that the robot stops rocking on its strings."""
    scenario = replace(Scenario.from_toml(CONFIG_DIR / "scenarios" / "hanging.toml"), base_damping=200.0)
    robot, frames, truths = record(scenario, 1.5)
    est, estimates = run(robot.info, frames, oracle_config(robot))
    return robot, frames, truths, estimates


def test_standing_still_torques_equal_the_true_torques(standing):
    """Standing at rest: torques equal the true ones (gravity sign, IMU frame) and the ankles carry m g."""
    robot, _, truths, estimates = standing
    mass = float(np.sum(robot.model.body_mass))
    for e in estimates[1200:1500:50]:
        assert e.valid
        truth = truth_at(truths, e.time)
        # 0.4 N m overall: the accelerometer bias (0.02 m/s^2) tilts the apparent gravity by 2 mrad,
        # ~0.25 N m on the chest pitch, computed from the waist side.
        assert np.allclose(e.tau[LEG], truth[LEG], atol=0.1) and np.allclose(e.tau, truth, atol=0.4)
        assert e.wrenches[0, 2] + e.wrenches[1, 2] == pytest.approx(mass * G, rel=0.02)
        assert e.residual_force < 3.0 and e.residual_torque < 1.0  # nothing else touches the robot
        assert e.base_specific_force[2] == pytest.approx(G, abs=0.1)


def test_hanging_still_leg_torques_equal_the_model_gravity_torques(hanging):
    """Hanging at rest: leg torques equal the true and model gravity torques; the unknown wrench is m g."""
    robot, _, truths, estimates = hanging
    model = load_pinocchio()
    data = model.createData()
    mass = float(np.sum(robot.model.body_mass))
    idx_v = [model.idx_vs[model.getJointId(j)] for j in robot.info.joint_names]
    for e in estimates[1000:1500:100]:
        truth = truths[int(round(e.time / robot.period)) - 1]
        q, _ = mujoco_to_pinocchio_state(*_state(robot, truth))
        gravity = pin.computeGeneralizedGravity(model, data, q)[idx_v]
        assert np.allclose(e.tau[LEG], truth_at(truths, e.time)[LEG], atol=0.15)
        assert np.allclose(e.tau[LEG], gravity[LEG], atol=0.35)
        assert np.linalg.norm(e.base_wrench[:3]) == pytest.approx(mass * G, rel=0.03)


def _state(robot: SimRobot, truth):
    """MuJoCo (qpos, qvel) of a ground truth (joints by name)."""
    m = robot.model
    qpos, qvel = np.zeros(m.nq), np.zeros(m.nv)
    qpos[0:3], qpos[3:7], qvel[0:6] = truth.base_position, truth.base_quat_wxyz, truth.base_velocity
    for i, name in enumerate(robot.info.joint_names):
        qpos[m.joint(name).qposadr[0]] = truth.q[i]
        qvel[m.joint(name).dofadr[0]] = truth.dq[i]
    return qpos, qvel


def test_moving_arm_without_contact_gives_a_near_zero_wrist_wrench(standing):
    """Arm and gripper moving without contact: the compensated wrist wrench stays near zero."""
    robot, frames, _, estimates = standing
    moving = [e for e in estimates[1700:] if e.valid]
    wrist = np.array([e.wrenches[2] for e in moving])
    raw = np.array([f.wrenches[2] for f in frames[1700:]])
    assert np.ptp(raw[:, :3], axis=0).max() > 2.0
    assert np.abs(wrist[:, :3]).max() < 0.5 and np.abs(wrist[:, 3:]).max() < 0.05


def test_update_reuses_one_holder_and_copy_is_independent(standing):
    """update() returns the same Estimate with the same arrays every tick; copy() does not change."""
    robot, frames, _, _ = standing
    est = TorqueEstimator(robot.info, oracle_config(robot))
    first = est.update(frames[0])
    arrays = (first.tau, first.q, first.wrenches)
    for f in frames[1:200]:
        e = est.update(f)
    kept = e.copy()
    again = est.update(frames[200])
    assert again is first and (again.tau, again.q, again.wrenches) == arrays
    assert kept.seq == frames[199].seq and again.seq == frames[200].seq
    assert not np.array_equal(kept.tau, again.tau)
    assert e.delay == pytest.approx(0.0395) and again.time == pytest.approx(frames[200].time - 0.0395)


def _faulty(frame: SensorFrame, **changes) -> SensorFrame:
    fields = {k: np.array(getattr(frame, k)) for k in ("q", "imu_angular_velocity", "imu_linear_acceleration",
                                                       "wrenches", "status")}
    for key, value in changes.items():
        fields[key] = value(fields[key])
    return replace(frame, **fields)


def test_nan_encoder_is_flagged_never_turned_into_a_torque_and_recovers(standing):
    """A NaN knee angle flags its dependent torques as NaN for one window, then the estimate recovers exactly."""
    robot, frames, _, clean = standing
    knee = robot.info.joint_index("RLEG_JOINT3")
    bad = list(frames)

    def nan_knee(q):
        q[knee] = np.nan
        return q

    for k in range(600, 605):
        bad[k] = _faulty(frames[k], q=nan_knee)
    _, est = run(robot.info, bad, oracle_config(robot))
    assert est[599].valid
    for k in (600, 640, 683):  # the last bad tick (604) leaves the 80-sample window at 684
        e = est[k]
        assert not e.valid and not e.tau_valid[0:6].any() and np.isnan(e.tau[0:6]).all()
        assert not e.tau_valid[12:14].any()  # chest: computed from the waist side, uses every input
        assert e.tau_valid[6:12].all() and np.isfinite(e.tau[6:12]).all()
        assert not e.encoders_valid[knee] and e.encoders_valid[knee + 1] and np.isnan(e.q[knee])
    for k in (684, 800):
        np.testing.assert_array_equal(est[k].tau, clean[k].tau)


@pytest.mark.parametrize("kind", ["stale", "nan"])
def test_bad_ft_or_imu_reading_is_flagged(standing, kind):
    """A stale right-ankle F/T reading flags only the joints that use it; a NaN IMU flags every torque."""
    robot, frames, _, clean = standing
    bad = list(frames)
    status = STATUS_STALE if kind == "stale" else STATUS_INVALID

    def flag_ankle(s):
        s[2] = status
        return s

    def flag_imu(s):
        s[1] = status
        return s

    for k in range(700, 710):
        if kind == "stale":
            bad[k] = _faulty(frames[k], status=flag_ankle)
        else:
            bad[k] = _faulty(frames[k], status=flag_imu, imu_linear_acceleration=lambda a: a * np.nan)
    _, est = run(robot.info, bad, oracle_config(robot))
    e = est[720]
    if kind == "stale":
        assert not e.wrenches_valid[0] and e.wrenches_valid[1:].all() and np.isnan(e.wrenches[0]).all()
        assert not e.tau_valid[0:6].any() and e.tau_valid[6:12].all() and e.tau_valid[14:].all()
    else:
        assert not e.imu_valid and not e.tau_valid.any() and np.isnan(e.tau).all()
    assert np.isnan(e.base_wrench).all() and not e.valid
    np.testing.assert_array_equal(est[800].tau, clean[800].tau)


def test_skipped_frames_are_a_counted_gap_interpolated_in_robot_time(standing):
    """Frames skipped while the arm moves: the estimate stays finite and on the time grid, the gap is counted and
    reported on its frame; a gap up to max_gap (20 ms) keeps it valid and close to the estimate without the gap; a
    longer one makes it invalid (still finite) for one window; a window after either gap, every torque is the
    one without the gap; a sequence number that goes back is refused."""
    robot, frames, _, clean = standing
    peak = np.abs(np.array([c.tau for c in clean[1500:]])).max(axis=0)
    est = TorqueEstimator(robot.info, oracle_config(robot))
    out = {}
    kept = frames[:1900] + frames[1904:2100] + frames[2160:2400]  # 4 frames skipped, then 60
    for f in kept:
        out[f.seq] = est.update(f).copy()
    assert (est.gaps, est.missing_frames, est.longest_gap) == (2, 64, 60)
    assert all(np.isfinite(e.tau).all() and np.isfinite(e.dq).all() and np.isfinite(e.ddq).all() for e in out.values()
               if e.seq >= frames[100].seq)
    short = out[frames[1904].seq]
    assert short.gap == 4 and short.valid and short.gap_flush == 0
    assert short.time == pytest.approx(clean[1904].time)
    for k in range(1904, 1990):
        assert out[frames[k].seq].valid
        assert np.all(np.abs(out[frames[k].seq].tau - clean[k].tau) <= 0.02 * np.maximum(peak, 1.0))
    long = out[frames[2160].seq]
    assert long.gap == 60 and not long.valid and long.gap_flush == 80
    assert np.isfinite(long.base_wrench).all() and np.isfinite(long.wrenches).all()
    assert not out[frames[2239].seq].valid and out[frames[2240].seq].valid
    for k in (1984, 2099, 2240, 2399):
        np.testing.assert_array_equal(out[frames[k].seq].tau, clean[k].tau)
    with pytest.raises(EstimationError, match="increasing"):
        est.update(frames[2399])


def test_shuffled_joint_order_gives_the_same_torques(standing):
    """A RobotInfo listing the joints in another order (frames permuted alike) gives the same torques."""
    robot, frames, _, clean = standing
    info = robot.info
    perm = np.random.default_rng(2).permutation(info.nq)
    shuffled = RobotInfo(name=info.name, joint_names=tuple(info.joint_names[i] for i in perm),
                         q_min=info.q_min[perm], q_max=info.q_max[perm], period=info.period,
                         model_path=info.model_path)
    est = TorqueEstimator(shuffled, oracle_config(robot))
    for k, f in enumerate(frames[:1300]):
        e = est.update(replace(f, q=f.q[perm]))
        if k in (1000, 1299):
            assert np.allclose(e.tau, clean[k].tau[perm], rtol=0.0, atol=1e-9)
            assert np.allclose(e.q, clean[k].q[perm], rtol=0.0, atol=1e-12)


def test_unknown_joint_name_in_robot_info_raises(standing):
    """A RobotInfo naming a joint the model does not have raises EstimationError at construction."""
    info = standing[0].info
    names = (*info.joint_names[:-1], "LARM_JOINT7")
    bad = RobotInfo(name="x", joint_names=names, q_min=info.q_min, q_max=info.q_max, period=info.period,
                    model_path=info.model_path)
    with pytest.raises(EstimationError, match="LARM_JOINT7"):
        TorqueEstimator(bad, EstimatorConfig())


@pytest.mark.parametrize("variant", ["centred", "low_delay"])
def test_derivatives_of_a_polynomial_through_the_estimator_are_exact(standing, variant):
    """Encoders on a polynomial of the filter's order give exact q, dq, ddq at the estimate's time stamp."""
    robot, frames, _, _ = standing
    config = EstimatorConfig.from_toml(variant=variant)
    est = TorqueEstimator(robot.info, config)
    dt, n = robot.period, robot.info.nq
    c = np.linspace(-0.3, 0.3, n)
    cubic = 0.4 if variant == "low_delay" else 0.0

    def poly(t):
        return 0.1 + c * t + 0.5 * t**2 + cubic * t**3, c + t + 3 * cubic * t**2, 1.0 + 6 * cubic * t

    template = frames[0]
    for k in range(150):
        q, _, _ = poly(k * dt)
        e = est.update(replace(template, time=k * dt, seq=k, q=q))
    q, dq, ddq = poly(e.time)
    assert e.delay == (0.0 if variant == "low_delay" else pytest.approx(0.0395))
    assert np.allclose(e.q, q, atol=1e-9) and np.allclose(e.dq, dq, atol=1e-7) and np.allclose(e.ddq, ddq, atol=1e-5)


def test_short_leg_swing_accuracy_against_the_truth():
    """Hanging 2.5 s leg swing: RMS torque error <= 0.75 N m and <= 12 % of the peak on the right leg."""

    def swing(t, q0):
        q = q0.copy()
        s = max(0.0, t - 0.5)
        q[0:6] += ramp(s) * np.array([0.15, -0.25, 0.4, 0.5, -0.3, -0.15]) * np.sin(
            2 * np.pi * np.array([0.5, 0.7, 0.35, 0.6, 0.8, 0.9]) * s)
        return q

    robot, frames, truths = record("hanging", 3.5, swing)
    _, estimates = run(robot.info, frames, oracle_config(robot))
    # The true torque has friction transients (Coulomb reversals) that the 80-sample filter cannot follow:
    # the ideal smoother of the truth itself is at ~10 % on the hip roll.
    kept = [e for e in estimates if e.valid and e.time > 1.5]
    err = np.array([e.tau - truth_at(truths, e.time) for e in kept])[:, 0:6]
    peak = np.abs(np.array([t.tau for t in truths if t.time > 1.5])[:, 0:6]).max(axis=0)
    rms = np.sqrt(np.mean(err**2, axis=0))
    assert np.all(rms <= 0.75), rms
    assert np.all(rms / peak <= 0.12), rms / peak
