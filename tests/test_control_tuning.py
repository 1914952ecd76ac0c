"""Tests of the loop's stability predicted from the identified model (control/stability.py, control/tuning.py), the
k_p schedule from its margin, and the velocity gain that follows the identified k_v (control/config.py,
``k7_per_k_v``)."""

import copy

import numpy as np
import pytest

from servotau.config import CONFIG_DIR, load_toml
from servotau.control import ControlConfig
from servotau.control.stability import LoopModel, dominant_mode, radius, spectral_radius, transition
from servotau.control.tuning import RHO_MAX, check_predicted_stable, predicted_radii, schedule_gains
from servotau.errors import ConfigError, ControlError

KNEE = dict(k_tau=5.17e-5, k_v=6.44e-3, inertia=0.88, period=1e-3, window=80, order=3)
# The hip pitch of the servo family's draw 0 (servo gain 10472 N m/rad, damping 39.2 N m s/rad: 0.38 of the nominal
# damping / sqrt(gain)), with its true k_tau and k_v, inertia and foot share at the start posture. At the paper's
# position feedback (q_hat), K6 = 1, K7 = 0.15 k_v, k_p = 0.5 it tripped in the simulator: a 20 Hz oscillation
# growing by 1.7 % per period (hip pitch alone in torque mode, linear servo, at rest).
HIP_PITCH_D0 = dict(k_tau=1 / 10472.0, k_v=39.19 / 10472.0, inertia=1.73, period=1e-3, window=80, order=3,
                    ft_inertia=0.415)


@pytest.fixture(scope="module")
def info():
    from servotau.simrobot.sim import SimConfig, SimRobot

    return SimRobot(SimConfig.named("hanging")).info


def config(info, **defaults):
    data = copy.deepcopy(load_toml(CONFIG_DIR / "control.toml").data)
    data["motors"] = defaults.pop("motors", data["motors"])
    data["joints"] = defaults.pop("joints", data.get("joints", {}))
    data["defaults"].update(defaults)
    if "k7_per_k_v" in defaults:
        data["defaults"].pop("k7", None)
    return ControlConfig.from_mapping(data, info)


def test_the_polynomial_roots_are_the_transition_matrix_eigenvalues():
    short = dict(window=20, ft_window=20)  # the same structure with fewer states: a quick eigenvalue problem
    for m, scale in ((LoopModel(**{**KNEE, "window": 20}), (1.0, 1.0)),
                     (LoopModel(**{**HIP_PITCH_D0, **short}), (1.25, 0.8)),
                     (LoopModel(**{**HIP_PITCH_D0, **short}, contact=False, encoder_position=True), (1.0, 1.0))):
        assert radius(m, 1.0, 0.15 * m.k_v, 0.5, scale) == pytest.approx(
                spectral_radius(transition(m, 1.0, 0.15 * m.k_v, 0.5, scale)), abs=1e-9)


def test_the_tripping_hip_pitch_is_predicted_unstable_at_20_hz_and_each_left_out_path_matters():
    """Known unstable: q_hat in the position error and the F/T path, the simulator's trip (20 Hz, +1.7 %/period).
    Without them (the encoder's q, no foot beyond a sensor) the same joint and gains look stable."""
    gains = (1.0, 0.15 * HIP_PITCH_D0["k_v"], 0.5)
    rho, hz = dominant_mode(LoopModel(**HIP_PITCH_D0), *gains)
    assert rho > RHO_MAX and 15.0 < hz < 25.0
    plain = {**HIP_PITCH_D0, "ft_inertia": 0.0}
    assert radius(LoopModel(**plain, encoder_position=True), *gains) < 1.0
    assert 1.0 < radius(LoopModel(**plain), *gains) < rho


def test_the_hip_pitch_is_stable_with_the_encoder_position_and_the_servo_damping_kept():
    """Known stable: the shipped law (position error from the encoder, K7 = k_v) with the k_p the schedule gives
    it; it ran without a trip in the simulator (draw 0, K6 = 1)."""
    m = LoopModel(**HIP_PITCH_D0, encoder_position=True)
    assert radius(m, 1.0, m.k_v, 0.125) < 1.0
    assert radius(m, 1.0, m.k_v, 0.125) < radius(m, 1.0, m.k_v, 1.0)  # the torque feedback is what rings


def test_loop_model_refuses_a_non_positive_k_tau():
    with pytest.raises(ControlError, match=r"LoopModel\.k_tau = -1.*expected a finite number > 0"):
        LoopModel(**{**KNEE, "k_tau": -1.0})


def test_shipped_config_passes_the_check_and_its_velocity_gain_follows_k_v(info):
    radii = check_predicted_stable(config(info), info, "motors/hrp2_sim_deadband.toml")
    assert set(radii) == set(config(info).torque_joints)
    assert all(r <= RHO_MAX for r in radii.values())
    cfg = config(info)
    knee = cfg.gains["RLEG_JOINT3"]
    m = cfg.motors["RLEG_JOINT3"]
    assert m.k_tau * (1 + knee.k_p) * knee.k_d == pytest.approx(m.k_v)  # k7 = k_v: the servo's damping kept


def test_the_schedule_lowers_k_p_where_the_margin_is_short_and_keeps_k6_and_k7(info):
    cfg = config(info)
    sched = schedule_gains(cfg, info)
    assert {j: g.k_p for j, g in sched.gains.items()} != {j: g.k_p for j, g in cfg.gains.items()}
    for j, g in sched.gains.items():
        m, g0 = cfg.motors[j], cfg.gains[j]
        assert g.k_p in (g0.k_p, g0.k_p / 2, g0.k_p / 4, 0.0)
        assert m.k_tau * (1 + g.k_p) * g.k_s == pytest.approx(m.k_tau * (1 + g0.k_p) * g0.k_s)  # K6
        assert m.k_tau * (1 + g.k_p) * g.k_d == pytest.approx(m.k_tau * (1 + g0.k_p) * g0.k_d)  # K7
    assert max(predicted_radii(sched, info).values()) < max(predicted_radii(cfg, info).values())


def test_a_model_predicting_a_ringing_torque_loop_is_refused_naming_the_joint(info, tmp_path):
    """A knee model 100 times softer than identified, with k_p = 3 there: the torque loop rings (radius >
    RHO_MAX)."""
    text = (CONFIG_DIR / "motors" / "hrp2_sim_identified.toml").read_text()
    head, rest = text.split("[joints.RLEG_JOINT3]", 1)
    line = next(v for v in rest.splitlines() if v.startswith("k_tau = "))
    soft = tmp_path / "m.toml"
    soft.write_text(head + "[joints.RLEG_JOINT3]" + rest.replace(line, f"k_tau = {100 * float(line[8:])!r}", 1))
    cfg = config(info, motors=str(soft), joints={"RLEG_JOINT3": {"k_p": 3.0}})
    assert predicted_radii(cfg, info)["RLEG_JOINT3"] > RHO_MAX
    with pytest.raises(ConfigError, match=r"m\.toml: joint \"RLEG_JOINT3\": fields 'joints\.RLEG_JOINT3\.k_tau'"):
        check_predicted_stable(cfg, info, str(soft))


def test_velocity_gain_as_a_share_of_the_identified_k_v(info):
    """k7_per_k_v: K7 = share * k_v of each joint (then / sqrt(K6) with inverse_sqrt_k6)."""
    cfg = config(info, k6=0.25, k7_per_k_v=0.2, k7_scaling="inverse_sqrt_k6")
    for j, g in cfg.gains.items():
        m = cfg.motors[j]
        k7 = m.k_tau * (1 + g.k_p) * g.k_d
        assert k7 == pytest.approx(0.2 * m.k_v / np.sqrt(0.25))


def test_k7_and_k7_per_k_v_together_are_refused(info):
    data = copy.deepcopy(load_toml(CONFIG_DIR / "control.toml").data)
    data["defaults"].update({"k7_per_k_v": 0.2, "k7": 0.001})
    with pytest.raises(ConfigError, match=r"k7.*either k7_per_k_v or k7, not both"):
        ControlConfig.from_mapping(data, info)
