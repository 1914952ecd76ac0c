"""Tests of the simulated HRP-2 (simrobot/sim.py, sensors.py, scenario.py)."""

import numpy as np
import pytest

from servotau.config import CONFIG_DIR
from servotau.errors import ConfigError
from servotau.hal.types import STATUS_INVALID, STATUS_OK, STATUS_STALE
from servotau.simrobot.scenario import OperatorPush, Scenario
from servotau.simrobot.sensors import SensorConfig, SensorFault
from servotau.simrobot.sim import SimConfig, SimRobot

G = 9.81  # [m/s^2]


def hold(robot: SimRobot, seconds: float, q=None):
    q = robot.read().q.copy() if q is None else q
    for _ in range(int(round(seconds / robot.period))):
        robot.step(q)
    return q


def test_standing_half_sitting_is_stable_and_feet_carry_the_weight():
    """Standing in half-sitting for 10 s: the robot stays put and the soles carry m*g within 2 %."""
    robot = SimRobot(SimConfig.named("standing"))
    start = robot.ground_truth()
    q0 = robot.read().q.copy()
    fz = []
    for k in range(10_000):
        robot.step(q0)
        if k % 100 == 0:
            fz.append(robot.ground_truth().sole_contact_forces[:, 2].sum())
    end = robot.ground_truth()
    mass = float(np.sum(robot.model.body_mass))
    assert np.linalg.norm(end.base_position - start.base_position) < 0.01
    assert np.max(np.abs(end.q - start.q)) < 0.01
    assert np.mean(fz[-20:]) == pytest.approx(mass * G, rel=0.02)
    assert np.all(np.abs(np.array(fz[-20:]) / (mass * G) - 1.0) < 0.02)


def test_ft_sign_convention_standing_reads_positive_fz():
    """Standing still, both ankle F/T sensors read fz > 0 (distal foot pushing on the leg)."""
    robot = SimRobot(SimConfig.named("standing"))
    hold(robot, 0.5)
    truth = robot.ground_truth()
    assert truth.wrenches[0, 2] > 200 and truth.wrenches[1, 2] > 200
    assert robot.read().imu_linear_acceleration[2] == pytest.approx(G, abs=0.3)


def test_hanging_feet_are_free_and_sensors_see_only_the_feet():
    """Hanging from the lift, the soles touch nothing and the ankle sensors read the foot weight."""
    robot = SimRobot(SimConfig.named("hanging"))
    hold(robot, 1.0)
    truth = robot.ground_truth()
    assert np.all(truth.sole_contact_forces == 0.0)
    foot_mass = robot.model.body("RLEG_FOOT").mass[0]
    assert truth.wrenches[0, 2] == pytest.approx(-foot_mass * G, rel=0.05)


def test_operator_push_loads_the_joints_and_the_sensor():
    """A scripted push on the hanging right foot shows in the ankle F/T and in the knee torque."""
    robot = SimRobot(SimConfig.named("hanging"))
    q0 = hold(robot, 0.5)
    knee = robot.info.joint_index("RLEG_JOINT3")
    before = robot.ground_truth()
    robot.add_push(OperatorPush(body="RLEG_FOOT", start=robot.time, duration=1.0, force=np.array([40.0, 0, 0]),
                                torque=np.zeros(3)))
    hold(robot, 0.5, q0)
    after = robot.ground_truth()
    assert np.allclose(after.external_wrench[:3], [40.0, 0, 0])
    assert abs(after.tau[knee] - before.tau[knee]) > 5.0
    assert np.linalg.norm(robot.read().wrenches[0, :3] - before.wrenches[0, :3]) > 30.0


def test_same_seed_gives_identical_frames_and_other_seed_differs():
    """Two runs with the same seed give bit-identical sensor frames; another seed changes the noise."""
    def run(seed):
        robot = SimRobot(SimConfig.named("hanging", seed=seed))
        frames = []
        for _ in range(200):
            robot.step(robot.read().q)
            frames.append(np.concatenate([robot.read().q, robot.read().wrenches.ravel()]))
        return np.array(frames)

    a, b, c = run(3), run(3), run(4)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_encoders_are_quantised_to_the_configured_resolution():
    """Encoder readings are multiples of the resolution; the truth is not."""
    robot = SimRobot(SimConfig.named("hanging"))
    hold(robot, 0.1)
    res = robot.config.sensors.encoder_resolution
    q = robot.read().q
    assert np.allclose(np.round(q / res) * res, q, atol=1e-12)
    assert np.max(np.abs(q - robot.ground_truth().q)) <= res / 2 + 1e-12


def test_sensor_faults_are_flagged_in_the_status():
    """A scripted NaN F/T reading and a stale IMU are flagged in the frame status."""
    sensors = SensorConfig.from_toml(CONFIG_DIR / "sensors.toml")
    faults = (SensorFault("right_ankle", "nan", 0.01, 0.02), SensorFault("imu", "stale", 0.01, 0.02))
    from dataclasses import replace

    robot = SimRobot(SimConfig.named("hanging", sensors=replace(sensors, faults=faults)))
    hold(robot, 0.005)
    assert robot.read().all_ok
    hold(robot, 0.01)
    f = robot.read()
    assert f.status[2] == STATUS_INVALID and np.all(np.isnan(f.wrenches[0]))
    assert f.status[1] == STATUS_STALE and f.status[0] == STATUS_OK
    hold(robot, 0.03)
    assert robot.read().all_ok


def test_force_scenario_puts_the_right_foot_on_the_block():
    """In the force scenario both feet touch: the right one on the block, 5 cm above the floor."""
    robot = SimRobot(SimConfig.named("force"))
    hold(robot, 1.0)
    truth = robot.ground_truth()
    assert truth.sole_contact_forces[0, 2] > 100 and truth.sole_contact_forces[1, 2] > 100
    assert robot.data.geom("right_sole").xpos[2] > 0.04


# -- hidden effects: each must leave its own physical signature --------------------------------
KNEE = "RLEG_JOINT3"


def swing(effects, seconds=3.0, amp=0.3, freq=0.8):
    """Swing the hanging right knee; return (q_des, q_meas, truth arrays) for the knee."""
    robot = SimRobot(SimConfig.named("hanging", effects=effects))
    j = robot.info.joint_index(KNEE)
    q0 = robot.read().q.copy()
    rows = []
    for k in range(int(seconds / robot.period)):
        q = q0.copy()
        q[j] += amp * np.sin(2 * np.pi * freq * k * robot.period)
        robot.step(q)
        g = robot.ground_truth()
        rows.append((q[j], robot.read().q[j], g.q[j], g.dq[j], g.tau[j], g.current[j], robot.time))
    a = np.array(rows)[500:]  # drop the start transient
    p = robot.servo.p
    return {"q_des": a[:, 0], "q_meas": a[:, 1], "q": a[:, 2], "dq": a[:, 3], "tau": a[:, 4], "i": a[:, 5],
            "t": a[:, 6], "k_t": p.k_t[j], "b": p.b[j], "kp": p.kp[j], "i_max": p.i_max[j]}


def friction(d):
    """Friction + ripple torque [N m] actually lost in the gear: motor torque minus transmitted."""
    return d["k_t"] * d["i"] - d["tau"]


def moving(d, lo, hi):
    s = np.abs(d["dq"])
    return (s > lo) & (s < hi)


def sig_coulomb_asym(d):
    up, down = d["dq"] > 0.05, d["dq"] < -0.05
    f = friction(d) - d["b"] * d["dq"]
    return np.mean(f[up]) + np.mean(f[down])  # 0 if symmetric, 2 * asymmetry otherwise


def sig_stribeck(d):
    f = np.abs(friction(d) - d["b"] * d["dq"])
    return np.mean(f[moving(d, 0.005, 0.05)]) - np.mean(f[moving(d, 0.5, 5)])


def sig_deadzone(d):
    return np.median(np.abs(d["q_des"] - d["q_meas"]) - np.abs(d["k_t"] * d["i"]) / d["kp"])


def sig_direction_gain(d):
    e = d["q_des"] - d["q_meas"]
    ratio = []
    for sel in (d["dq"] > 0.05, d["dq"] < -0.05):
        sel = sel & (np.abs(d["i"]) < 0.9 * d["i_max"])
        ratio.append(np.linalg.lstsq(np.c_[e[sel], -d["dq"][sel]], d["k_t"] * d["i"][sel], rcond=None)[0][0])
    return ratio[0] / ratio[1] - 1.0


def sig_link_motor_gap(d):
    return np.max(np.abs(d["q_meas"] - d["q"]))


def sig_load_friction(d):
    sel = moving(d, 0.1, 5)
    f = np.abs(friction(d) - d["b"] * d["dq"])[sel]
    return np.corrcoef(f, np.abs(d["tau"][sel]))[0, 1]


def sig_cogging(d):
    sel = np.abs(d["dq"]) > 0.05
    f = (friction(d) - d["b"] * d["dq"] - 2.5 * np.tanh(d["dq"] / 0.01))[sel]
    ph = 2 * np.pi * d["q"][sel] / 0.08
    basis = np.c_[np.sin(ph), np.cos(ph), np.ones_like(ph)]
    c = np.linalg.lstsq(basis, f, rcond=None)[0]
    return np.hypot(c[0], c[1])


def sig_thermal(d):
    f = np.abs(friction(d))
    n = len(f) // 2
    sel = moving(d, 0.3, 5)
    return np.mean(f[:n][sel[:n]]) - np.mean(f[n:][sel[n:]])


def sig_saturation(d):
    return np.mean(np.abs(d["i"]) >= d["i_max"] - 1e-9)


def sig_delay(d):
    """The command lag [ticks] that best explains the motor torque by a PD on the position error."""
    tau_m, n = d["k_t"] * d["i"], len(d["i"])
    sel = np.abs(d["i"]) < 0.9 * d["i_max"]
    resid = []
    for k in range(30):
        e = d["q_des"][30 - k : n - k] - d["q_meas"][30:]
        A = np.c_[e, d["dq"][30:], np.ones(n - 30)][sel[30:]]
        resid.append(np.linalg.lstsq(A, tau_m[30:][sel[30:]], rcond=None)[1][0])
    return float(np.argmin(resid))


SIGNATURES = {
    "coulomb_asym": (sig_coulomb_asym, 4.0),
    "stribeck": (sig_stribeck, 3.0),
    "deadzone": (sig_deadzone, 2e-3),
    "direction_gain": (sig_direction_gain, 0.4),
    "backlash": (sig_link_motor_gap, 1e-3),
    "load_friction": (sig_load_friction, 0.3),
    "cogging": (sig_cogging, 2.0),
    "thermal_drift": (sig_thermal, 1.0),
    "saturation": (sig_saturation, 0.05),
    "delay": (sig_delay, 5.0),
    "elastic": (sig_link_motor_gap, 1e-3),
}


@pytest.fixture(scope="module")
def baseline():
    return swing(None)


@pytest.mark.parametrize("effect", sorted(SIGNATURES))
def test_each_hidden_effect_leaves_its_signature(effect, baseline):
    """Switching one hidden effect on (knee only) moves its own signature statistic by a clear margin."""
    sig, margin = SIGNATURES[effect]
    data = swing({effect: {"joints": [KNEE]}})
    assert abs(sig(data) - sig(baseline)) > margin, (sig(data), sig(baseline))


def test_unknown_scenario_field_and_bad_values_fail_clearly(tmp_path):
    """A bad scenario file names the file, the field and the expected value."""
    p = tmp_path / "bad.toml"
    p.write_text('name = "x"\nbase_height = -1.0\n')
    with pytest.raises(ConfigError, match=r"bad.toml: field 'base_height' = -1.0: expected a finite number >= 0"):
        Scenario.from_toml(p)
    p.write_text('name = "x"\nbase_hieght = 1.0\n')
    with pytest.raises(ConfigError, match=r"field 'base_hieght'.*a known field"):
        Scenario.from_toml(p)


def test_bad_command_is_rejected_and_does_not_move_the_robot():
    """A NaN or wrongly sized desired-angle vector raises and leaves the simulation untouched."""
    robot = SimRobot(SimConfig.named("hanging"))
    seq, q = robot.seq, robot.ground_truth().q
    bad = robot.read().q.copy()
    bad[3] = np.nan
    for cmd in (bad, np.zeros(5)):
        with pytest.raises(ConfigError, match="q_des"):
            robot.step(cmd)
    assert robot.seq == seq and np.array_equal(robot.ground_truth().q, q)


def test_scenario_operator_and_sim_files_take_the_dataclass_defaults(tmp_path):
    """Keys left out take the dataclass defaults; an [[operator]] or [[faults]] error names its entry."""
    p = tmp_path / "s.toml"
    p.write_text('name = "x"\n[[operator]]\nbody = "RLEG_FOOT"\nstart = 1.0\nduration = 2.0\nforce = [1, 2, 3]\n')
    s = Scenario.from_toml(p)
    assert s == Scenario("x", operator=s.operator) and s.operator[0].force.tolist() == [1.0, 2.0, 3.0]
    push = s.operator[0]
    assert (push.profile, push.frequency, push.torque.tolist()) == ("constant", 0.5, [0.0, 0.0, 0.0])
    p.write_text('name = "x"\n[[operator]]\nbody = "RLEG_FOOT"\nstart = 1.0\nduration = 0.0\n')
    with pytest.raises(ConfigError, match=r"field 'operator\[0\].duration' = 0.0: expected a finite number > 0 \[s\]"):
        Scenario.from_toml(p)
    sim = tmp_path / "sim.toml"
    sim.write_text(f'scenario = "{CONFIG_DIR / "scenarios" / "hanging.toml"}"\n')
    cfg = SimConfig.from_toml(sim)
    assert cfg.seed == 0 and cfg.servo_path == CONFIG_DIR / "servo.toml" and cfg.effects is None
    sensors = tmp_path / "sensors.toml"
    sensors.write_text((CONFIG_DIR / "sensors.toml").read_text() + '[[faults]]\nsensor = "imu"\nkind = "inf"\n'
                                                                   'start = 0.0\nduration = 1.0\n')
    with pytest.raises(ConfigError, match=r"field 'faults\[0\].kind' = 'inf': expected one of \['nan', 'stale'\]"):
        SensorConfig.from_toml(sensors)


def test_sensor_file_errors_name_the_table_key(tmp_path):
    """A sensors file's keys are checked with SensorConfig's units and bounds, named by table and key."""
    text = (CONFIG_DIR / "sensors.toml").read_text()
    p = tmp_path / "sensors.toml"
    p.write_text(text.replace("resolution = 1.0e-5", "resolution = -1.0"))
    with pytest.raises(ConfigError, match=r"field 'encoders.resolution' = -1.0: expected a finite number >= 0 \[rad\]"):
        SensorConfig.from_toml(p)
    p.write_text(text.replace("offset_scale = [3.0, 0.3]", "offset_scale = [3.0]"))
    with pytest.raises(ConfigError, match=r"field 'ft.offset_scale' = \[3.0\]: expected a list of 2 finite numbers"):
        SensorConfig.from_toml(p)
