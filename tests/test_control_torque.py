"""Tests of servotau.control.torque: the joint-torque controller of the paper's eq. 10-11."""

import numpy as np
import pytest

from servotau.config import CONFIG_DIR
from servotau.control.config import JointGains
from servotau.control.torque import JointTorqueController
from servotau.errors import ControlError, IdentificationError
from servotau.identification.motor_params import MotorModel, MotorParameters
from servotau.simrobot.model import JOINT_NAMES

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


def test_extra_effect_terms_follow_the_motor_model():
    """Extra terms: used as MotorModel.predict evaluates them, or ignored (and listed) if it cannot."""
    motors = MotorParameters.load_toml(CONFIG_DIR / "motors" / "example.toml")
    ankle = "RLEG_JOINT5"
    assert motors[ankle].extra
    tc = JointTorqueController(JOINT_NAMES, motors, {ankle: JointGains(k_p=0.0)}, 1e-3, 1e-6)
    i = JOINT_NAMES.index(ankle)
    tau, dq = np.zeros(30), np.zeros(30)
    tau[i], dq[i] = 12.0, 0.4
    dq_err = tc.update(tau, tau, dq)[i]
    m = motors[ankle]
    try:
        expected = float(m.predict(np.array([12.0]), np.array([0.4]))[0])
        assert ankle not in tc.ignored_effects
    except IdentificationError:
        expected = m.k_tau * 12.0 + m.k_v * 0.4 + (m.k_c or 0.0)
        assert tc.ignored_effects == {ankle: list(m.extra)}
    assert dq_err == pytest.approx(expected, rel=1e-6)


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
