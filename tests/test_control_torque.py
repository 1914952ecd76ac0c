"""Tests of servotau.control.torque: the joint-torque controller of the paper's eq. 10-11."""

import numpy as np
import pytest

from servotau.actuator import MotorModel, MotorParameters
from servotau.config import CONFIG_DIR
from servotau.control.config import JointGains
from servotau.control.torque import JointTorqueController
from servotau.description import JOINT_NAMES
from servotau.errors import ConfigError, ControlError

KNEE = JOINT_NAMES.index("RLEG_JOINT3")
MOTORS = {"RLEG_JOINT3": MotorModel(k_tau=5.1e-5, k_v=0.006561, k_c=2e-4, provenance="test"),
          "RLEG_JOINT2": MotorModel(k_tau=1.2e-4, k_v=0.007, provenance="test")}


def _controller(k_p=2.0, k_i=0.0, limit=10.0, sign_velocity=0.01):
    gains = {j: JointGains(k_p=k_p, k_i=k_i, integral_limit=limit) for j in MOTORS}
    return JointTorqueController(JOINT_NAMES, MOTORS, gains, 1e-3, sign_velocity)


def test_command_is_ktau_tau_star_plus_friction():
    """dq_err = k_tau (tau_d + k_p (tau_d - tau_hat)) + k_v dq + k_c tanh(dq / v_s), per joint (eq. 10-11)."""
    tc = _controller(k_p=2.0)
    tau_d, tau_hat, dq = np.full(30, 40.0), np.full(30, 35.0), np.full(30, 0.3)
    dq_err = tc.update(tau_d, tau_hat, dq)
    m = MOTORS["RLEG_JOINT3"]
    expected = m.k_tau * (40.0 + 2.0 * 5.0) + m.k_v * 0.3 + m.k_c * np.tanh(0.3 / 0.01)
    assert dq_err[KNEE] == pytest.approx(expected, rel=1e-12)
    assert tc.tau_star[KNEE] == pytest.approx(50.0)
    assert tc.e_tau[KNEE] == pytest.approx(5.0)


def test_position_controlled_joints_get_zero():
    """Joints without gains have every gain 0: their command offset is 0."""
    dq_err = _controller().update(np.full(30, 40.0), np.full(30, 35.0), np.full(30, 0.3))
    others = np.ones(30, dtype=bool)
    others[[KNEE, JOINT_NAMES.index("RLEG_JOINT2")]] = False
    assert np.all(dq_err[others] == 0.0)


def test_coulomb_sign_is_smoothed():
    """Around zero velocity the Coulomb term is k_c tanh(dq / v_s): continuous, not a jump."""
    tc = _controller(k_p=0.0, sign_velocity=0.05)
    dq = np.zeros(30)
    dq[KNEE] = 0.005
    tc.update(np.zeros(30), np.zeros(30), dq)
    m = MOTORS["RLEG_JOINT3"]
    assert tc.friction[KNEE] == pytest.approx(m.k_v * 0.005 + m.k_c * np.tanh(0.1))
    assert tc.friction[KNEE] < 0.5 * m.k_c  # a plain sign would give the full k_c


def test_integral_is_clamped_without_windup():
    """With k_i > 0 the integral term saturates at integral_limit and recovers at once when the error reverses."""
    tc = _controller(k_p=0.0, k_i=10.0, limit=5.0)
    tau_hat = np.zeros(30)
    tau_d = np.full(30, 100.0)
    for _ in range(1000):  # 1 s of a 100 N m error: 1000 N m unclamped
        tc.update(tau_d, tau_hat, np.zeros(30))
    assert tc.integral_term[KNEE] == pytest.approx(5.0)
    tc.update(-tau_d, tau_hat, np.zeros(30))
    assert tc.integral_term[KNEE] == pytest.approx(5.0 - 10.0 * 100.0 * 1e-3)
    tc.reset()
    assert not tc.integral.any() and not tc.integral_term.any()


MOTORS_WITH_EXTRA = """version = 1

[joints.RLEG_JOINT3]
k_tau = 5.1e-05
k_v = 0.006561
loss = "asymmetric"
w = 100.0
provenance = "test"

[joints.RLEG_JOINT3.extra.deadzone]
coefficient = 0.0004
shape = { band = 0.0003, damping_share = 0.33 }

[joints.RLEG_JOINT3.extra.stribeck]
coefficient = 0.0007
shape = { v_s = 0.04, v_eps = 0.01 }

[joints.RLEG_JOINT3.extra.cogging]
coefficient = 0.0002
shape = { period = 0.08, phase = 0.3 }

[joints.RLEG_JOINT3.extra.motor_lag]
coefficient = 0.5
shape = { time_constant = 0.02 }
"""


def _extra_file(tmp_path, text=MOTORS_WITH_EXTRA):
    path = tmp_path / "motors.toml"
    path.write_text(text)
    return path


def _knee_controller(tmp_path):
    """The knee's motor model of MOTORS_WITH_EXTRA and a controller torque-controlling the knee with it."""
    motors = MotorParameters.load_toml(_extra_file(tmp_path))
    return motors["RLEG_JOINT3"], JointTorqueController(JOINT_NAMES, motors, {"RLEG_JOINT3": JointGains(k_p=0.5)},
                                                        1e-3)


def test_extra_terms_of_the_motor_file_change_the_command_as_the_model_predicts(tmp_path):
    """With extra terms in the file, dq_err is the model's prediction at (tau*, dq, q, t), tick by tick."""
    knee, tc = _knee_controller(tmp_path)
    rng = np.random.default_rng(1)
    ticks = 300
    t = 1e-3 * np.arange(ticks)
    tau_d, tau_hat = 30 * np.sin(2 * np.pi * t), rng.normal(0, 3, ticks)
    dq = 0.3 * np.sin(2 * np.pi * 2 * t) + rng.normal(0, 0.01, ticks)
    q = 0.8 + 0.05 * np.cos(2 * np.pi * 2 * t)
    got, tau_star, linear = np.zeros(ticks), np.zeros(ticks), np.zeros(ticks)
    vec = {k: np.zeros(30) for k in ("tau_d", "tau_hat", "dq", "q")}
    for k in range(ticks):
        for name, v in (("tau_d", tau_d), ("tau_hat", tau_hat), ("dq", dq), ("q", q)):
            vec[name][KNEE] = v[k]
        got[k] = tc.update(vec["tau_d"], vec["tau_hat"], vec["dq"], vec["q"], np.zeros(30), t[k])[KNEE]
        tau_star[k] = tc.tau_star[KNEE]
        linear[k] = knee.k_tau * tau_star[k] + knee.k_v * dq[k]
        assert tc.extra[KNEE] == pytest.approx(got[k] - linear[k], abs=1e-15)
    # The workbench's batch evaluation of the same model on the same signals (an independent code path).
    expected = knee.predict(tau_star, dq, q=q, t=t)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert np.max(np.abs(got - linear)) > 1e-4  # the extra terms do change the command (by up to ~1 mrad)
    others = np.ones(30, dtype=bool)
    others[KNEE] = False
    assert not tc.extra[others].any()


def test_direction_terms_read_dq_sign_and_the_viscous_term_dq_hat(tmp_path):
    """With ``dq_sign`` (velocity_feedforward = "reference_signs"), the extra terms are the model's at dq_sign and
    the viscous term stays K_v dq_hat: dq_err = model(tau*, dq_sign) + K_v (dq_hat - dq_sign)."""
    knee, tc = _knee_controller(tmp_path)
    rng = np.random.default_rng(2)
    ticks = 200
    t = 1e-3 * np.arange(ticks)
    dq_ref = 0.3 * np.sin(2 * np.pi * 2 * t)  # the reference's velocity
    dq_est = dq_ref + rng.normal(0, 0.02, ticks)  # the estimate: noisy around it
    got, tau_star = np.zeros(ticks), np.zeros(ticks)
    vec = {k: np.zeros(30) for k in ("tau_d", "tau_hat", "dq_hat", "dq_sign", "q")}
    for k in range(ticks):
        for name, v in (("tau_d", 30 * np.sin(2 * np.pi * t[k])), ("tau_hat", 0.0), ("dq_hat", dq_est[k]),
                        ("dq_sign", dq_ref[k]), ("q", 0.8)):
            vec[name][KNEE] = v
        got[k] = tc.update(vec["tau_d"], vec["tau_hat"], vec["dq_hat"], vec["q"], np.zeros(30), t[k],
                           dq_sign=vec["dq_sign"])[KNEE]
        tau_star[k] = tc.tau_star[KNEE]
        assert tc.friction[KNEE] == pytest.approx(knee.k_v * dq_est[k], abs=1e-15)
    expected = knee.predict(tau_star, dq_ref, q=np.full(ticks, 0.8), t=t) + knee.k_v * (dq_est - dq_ref)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


def test_delay_term_solves_the_command_it_reads(tmp_path):
    """A `delay` term reads this tick's q_des: the controller's command satisfies q_des - q = model(q_des)."""
    text = MOTORS_WITH_EXTRA.split("[joints.RLEG_JOINT3.extra.deadzone]")[0]
    text += "[joints.RLEG_JOINT3.extra.delay]\ncoefficient = 0.6\nshape = { delay = 0.005 }\n"
    motors = MotorParameters.load_toml(_extra_file(tmp_path, text))
    knee = motors["RLEG_JOINT3"]
    tc = JointTorqueController(JOINT_NAMES, motors, {"RLEG_JOINT3": JointGains(k_p=0.0)}, 1e-3)
    tau, dq, q = np.zeros(30), np.zeros(30), np.zeros(30)
    q_des = []
    for k in range(40):
        tau[KNEE], dq[KNEE], q[KNEE] = 20.0 * (k >= 10), 0.1, 0.5 + 1e-4 * k
        dq_err = tc.update(tau, tau, dq, q, np.zeros(30), 1e-3 * k)[KNEE]
        q_des.append(q[KNEE] + dq_err)
        delayed = q_des[k - 5] if k >= 5 else q_des[0]
        model = knee.k_tau * tau[KNEE] + knee.k_v * dq[KNEE] + 0.6 * (q_des[k] - delayed)
        assert dq_err == pytest.approx(model, abs=1e-12)
    assert max(abs(d) for d in np.diff(q_des)) > 2e-3  # the torque step moved the command through the term


def test_deadzone_crossing_term_follows_the_command_it_sent(tmp_path):
    """The dead zone's crossing form reads the previous tick's command: the controller's commands are the batch
    model on the commands it sent, and a desired torque through zero moves the command across the band."""
    text = MOTORS_WITH_EXTRA.split("[joints.RLEG_JOINT3.extra.deadzone]")[0]
    text += ("[joints.RLEG_JOINT3.extra.deadzone]\ncoefficient = 0.003\n"
             "shape = { band = 0.0003, damping_share = 0.0, crossing = 1.0, width = 0.003 }\n")
    motors = MotorParameters.load_toml(_extra_file(tmp_path, text))
    knee = motors["RLEG_JOINT3"]
    tc = JointTorqueController(JOINT_NAMES, motors, {"RLEG_JOINT3": JointGains(k_p=0.0)}, 1e-3)
    ticks = 60
    tau_d = np.linspace(20.0, -20.0, ticks)  # [N m] through zero: u crosses the band
    q = 0.5 + 1e-5 * np.arange(ticks)  # [rad] the joint creeps
    tau, dq, qv, q_des = np.zeros(30), np.zeros(30), np.zeros(30), np.zeros(ticks)
    for k in range(ticks):
        tau[KNEE], qv[KNEE] = tau_d[k], q[k]
        q_des[k] = q[k] + tc.update(tau, tau, dq, qv, np.zeros(30), 1e-3 * k)[KNEE]
    np.testing.assert_allclose(q_des - q, knee.predict(tau_d, np.zeros(ticks), q=q, q_des=q_des), atol=1e-12)
    assert q_des[0] - q[0] > 3e-3 and q_des[-1] - q[-1] < -3e-3  # from one edge of the band to the other


def test_unknown_extra_term_is_a_config_error_naming_the_file_and_field(tmp_path):
    """A term the workbench does not know (or a wrong shape) raises ConfigError naming the file and the field."""
    from servotau.config import load_toml
    from servotau.control.config import ControlConfig
    from servotau.simrobot.sim import SimConfig, SimRobot

    info = SimRobot(SimConfig.named("hanging", seed=0)).info
    data = load_toml(CONFIG_DIR / "control.toml").data
    text = MOTORS_WITH_EXTRA.replace("[joints.RLEG_JOINT3.extra.cogging]", "[joints.RLEG_JOINT3.extra.gear_whine]")
    for joint in ("RLEG_JOINT0", "RLEG_JOINT1", "RLEG_JOINT2", "RLEG_JOINT4", "RLEG_JOINT5"):
        text += f'[joints.{joint}]\nk_tau = 1e-4\nk_v = 0.007\nloss = "least_squares"\nprovenance = "test"\n'
    path = _extra_file(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        ControlConfig.from_mapping({**data, "motors": str(path)}, info, file="ctl.toml")
    msg = str(err.value)
    assert str(path) in msg and "joints.RLEG_JOINT3.extra.gear_whine" in msg and "expected one of" in msg, msg
    assert "cogging" in msg  # the known effects are listed
    path.write_text(text.replace("gear_whine]", "cogging]").replace("period = 0.08", "wavelength = 0.08"))
    with pytest.raises(ConfigError, match=r"joints\.RLEG_JOINT3\.extra\.cogging.*wavelength"):
        ControlConfig.from_mapping({**data, "motors": str(path)}, info, file="ctl.toml")
    with pytest.raises(ControlError, match="RLEG_JOINT3.*gear_whine"):  # built directly: ControlError
        bad = MotorParameters.load_toml(_extra_file(tmp_path, MOTORS_WITH_EXTRA.replace("cogging]", "gear_whine]")))
        JointTorqueController(JOINT_NAMES, bad, {"RLEG_JOINT3": JointGains()}, 1e-3)


def test_missing_motor_model_or_unknown_joint_raise():
    """Gains for a joint without a motor model, or for an unknown joint, raise ControlError naming it."""
    with pytest.raises(ControlError, match="LLEG_JOINT3"):
        JointTorqueController(JOINT_NAMES, MOTORS, {"LLEG_JOINT3": JointGains()}, 1e-3)
    with pytest.raises(ControlError, match="KNEE"):
        JointTorqueController(JOINT_NAMES, MOTORS, {"KNEE": JointGains()}, 1e-3)
    with pytest.raises(ControlError, match="period"):
        JointTorqueController(JOINT_NAMES, MOTORS, {}, 0.0)
    with pytest.raises(ControlError, match="sign_velocity"):
        JointTorqueController(JOINT_NAMES, MOTORS, {}, 1e-3, -1.0)


def test_a_model_without_k_tau_or_with_an_offset_is_refused_naming_the_joint_and_key():
    """A model the workbench saved for another use (no torque term, a constant) is not a feedforward."""
    for model, key in ((MotorModel(k_tau=None, k_v=0.01, provenance="test"), "k_tau"),
                       (MotorModel(k_tau=1e-4, k_v=0.01, offset=1e-3, provenance="test"), "offset")):
        with pytest.raises(ControlError, match=f'"RLEG_JOINT3".*{key}'):
            JointTorqueController(JOINT_NAMES, {"RLEG_JOINT3": model}, {"RLEG_JOINT3": JointGains()}, 1e-3)
