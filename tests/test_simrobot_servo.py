"""Tests of the closed position servo model (simrobot/servo.py) and its config file."""

import numpy as np
import pytest

from servotau.config import CONFIG_DIR
from servotau.errors import ConfigError
from servotau.simrobot.servo import EFFECTS, Servo
from servotau.simrobot.servo_config import EFFECT_PARAMS, load_servo_params

JOINTS = ("J0", "J1", "J2")


def write_servo(tmp_path, body: str):
    p = tmp_path / "servo.toml"
    p.write_text(
        '[defaults]\ni_deadzone = 0.2\ni_max = 10.0\ng_dir = 0.0\nv_eps = 0.01\nv_s = 0.05\ntau_s = 0.0\n'
        '[groups.all]\njoints = "all"\nkp = 10000.0\nkd = 50.0\nk_t = 10.0\nb = 20.0\ntau_c = 1.0\n' + body
    )
    return p


def make_servo(tmp_path, body="", effects=None):
    params = load_servo_params(write_servo(tmp_path, body), JOINTS, np.full(3, 0.3), effects)
    return Servo(params, 1e-3)


def test_static_slope_is_stiffness_outside_dead_zone(tmp_path):
    """At rest, d(torque)/d(error) equals kp outside the driver dead zone and is zero inside it."""
    sv = make_servo(tmp_path)
    e = np.linspace(-0.01, 0.01, 2001)
    tau = np.array([sv.motor_torque(np.full(3, x), np.zeros(3), np.zeros(3))[0] for x in e])
    e_dz = 0.2 * 10.0 / 10000.0  # i_deadzone * k_t / kp [rad]
    outside = np.abs(e) > e_dz + 1e-5
    slope = np.polyfit(e[outside & (e > 0)], tau[outside & (e > 0)], 1)[0]
    assert slope == pytest.approx(10000.0, rel=1e-9)
    assert np.all(tau[np.abs(e) < e_dz - 1e-6] == 0.0)


def test_current_saturation_caps_torque(tmp_path):
    """Large errors saturate the current at i_max, so the torque stops at k_t * i_max."""
    sv = make_servo(tmp_path)
    tau = sv.motor_torque(np.full(3, 1.0), np.zeros(3), np.zeros(3))
    assert np.allclose(tau, 10.0 * 10.0)
    assert np.allclose(sv.current, 10.0)


def test_friction_opposes_motion_and_grows_with_speed(tmp_path):
    """Friction has the sign of the velocity and includes the viscous and Coulomb parts."""
    sv = make_servo(tmp_path)
    f = sv.friction(np.zeros(3), np.array([-1.0, 0.0, 1.0]))
    assert f[0] == pytest.approx(-21.0, rel=1e-6) and f[1] == 0.0 and f[2] == pytest.approx(21.0, rel=1e-6)


def test_command_delay_effect_delays_by_ticks(tmp_path):
    """The delay effect makes the servo see the command `delay_ticks` ticks late."""
    sv = make_servo(tmp_path, effects={"delay": {"joints": ["J1"], "delay_ticks": 3}})
    seen = [sv.delayed_command(np.full(3, float(k)))[1] for k in range(10)]
    assert seen[3:] == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert [sv.delayed_command(np.full(3, 20.0))[0]] == [20.0]


def test_every_effect_has_parameters_and_is_off_by_default(tmp_path):
    """All the hidden effects are known to the config loader and none is on in config/servo.toml."""
    assert set(EFFECT_PARAMS) == set(EFFECTS)
    from servotau.description import JOINT_NAMES

    p = load_servo_params(CONFIG_DIR / "servo.toml", JOINT_NAMES, np.full(30, 0.1))
    for f in ("tau_c_asym", "e_deadzone", "mu_load", "cog_amp", "thermal_alpha", "gear_k", "backlash"):
        assert np.all(getattr(p, f) == 0.0), f
    assert np.all(p.delay_ticks == 0)


def test_default_servo_matches_real_hrp2_leg_within_factor_two():
    """Nominal k_tau and k_v of the default right-leg servo are within x2 of the real robot's."""
    from servotau.description import JOINT_NAMES

    p = load_servo_params(CONFIG_DIR / "servo.toml", JOINT_NAMES, np.full(30, 0.1))
    real_k_tau = np.array([2.12e-4, 3.0e-5, 1.2e-4, 5.1e-5, 1.77e-4, 2.4e-4])
    real_k_v = np.array([0.013, 0.006332, 0.007, 0.006561, 0.00693, 0.006])
    for got, real in ((p.k_tau_nominal()[:6], real_k_tau), (p.k_v_nominal()[:6], real_k_v)):
        assert np.all(got / real < 2.0) and np.all(real / got < 2.0)


@pytest.mark.parametrize(
    "body, field, expected",
    [
        ("[joints.J9]\nkp = 1.0\n", "joints.J9", "a joint name"),
        ("[joints.J0]\nkp = -5.0\n", "joints.J0.kp", "> 0"),
        ("[joints.J0]\nkd = nan\n", "joints.J0.kd", "a finite number"),
        ("[effects.cogging]\njoints = [\"J7\"]\n", "effects.cogging.joints", "a joint name"),
        ("[effects.magic]\njoints = \"all\"\n", "effects.magic", "a hidden effect"),
        ("[joints.J0]\nkpp = 1.0\n", "joints.J0.kpp", "a known field"),
    ],
)
def test_bad_config_names_field_and_expected_value(tmp_path, body, field, expected):
    """A bad servo file fails with an error naming the file, the field and the expected value."""
    with pytest.raises(ConfigError) as err:
        make_servo(tmp_path, body)
    msg = str(err.value)
    assert "servo.toml" in msg and f"'{field}'" in msg and expected in msg
