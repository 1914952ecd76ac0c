"""Tests of the loop's stability predicted from the identified model (control/stability.py, control/tuning.py) and
of the velocity gain that follows the identified k_v (control/config.py, ``k7_per_k_v``)."""

import copy

import numpy as np
import pytest

from servotau.config import CONFIG_DIR, load_toml
from servotau.control import ControlConfig
from servotau.control.stability import LoopModel, radius
from servotau.control.tuning import RHO_MAX, check_predicted_stable, predicted_radii
from servotau.errors import ConfigError, ControlError

KNEE = dict(k_tau=5.17e-5, k_v=6.44e-3, inertia=0.88, period=1e-3, window=80, order=3)


@pytest.fixture(scope="module")
def info():
    from servotau.simrobot.sim import SimConfig, SimRobot

    return SimRobot(SimConfig.named("hanging")).info


def config(info, **defaults):
    data = copy.deepcopy(load_toml(CONFIG_DIR / "control.toml").data)
    data["motors"] = defaults.pop("motors", data["motors"])
    data["defaults"].update(defaults)
    if "k7_per_k_v" in defaults:
        data["defaults"].pop("k7", None)
    return ControlConfig.from_mapping(data, info)


def test_a_stiff_loop_without_delay_is_stable_and_the_velocity_gain_moves_the_radius():
    m = LoopModel(**KNEE)
    assert radius(m, 1.0, 0.004, 0.5) < 1.0
    assert radius(m, 1.0, 0.004, 0.5) != radius(m, 1.0, 0.0, 0.5)


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
    assert m.k_tau * (1 + knee.k_p) * knee.k_d == pytest.approx(0.15 * m.k_v)  # K6 = 1: k7 = 0.15 k_v


def test_a_model_predicting_a_ringing_torque_loop_is_refused_naming_the_joint(info, tmp_path):
    """A knee model 100 times softer than identified, with k_p = 3: the torque loop rings (radius > RHO_MAX)."""
    text = (CONFIG_DIR / "motors" / "hrp2_sim_identified.toml").read_text()
    head, rest = text.split("[joints.RLEG_JOINT3]", 1)
    line = next(v for v in rest.splitlines() if v.startswith("k_tau = "))
    soft = tmp_path / "m.toml"
    soft.write_text(head + "[joints.RLEG_JOINT3]" + rest.replace(line, f"k_tau = {100 * float(line[8:])!r}", 1))
    cfg = config(info, k_p=3.0, motors=str(soft))
    assert predicted_radii(cfg, info)["RLEG_JOINT3"] > RHO_MAX
    with pytest.raises(ConfigError, match=r"m\.toml: joint \"RLEG_JOINT3\": fields 'joints\.RLEG_JOINT3\.k_tau'"):
        check_predicted_stable(cfg, info, str(soft))


def test_velocity_gain_as_a_share_of_the_identified_k_v(info):
    """k7_per_k_v: K7 = share * k_v of each joint (then / sqrt(K6) with inverse_sqrt_k6)."""
    cfg = config(info, k6=0.25, k7_per_k_v=0.2)
    for j, g in cfg.gains.items():
        m = cfg.motors[j]
        k7 = m.k_tau * (1 + g.k_p) * g.k_d
        assert k7 == pytest.approx(0.2 * m.k_v / np.sqrt(0.25))


def test_k7_and_k7_per_k_v_together_are_refused(info):
    data = copy.deepcopy(load_toml(CONFIG_DIR / "control.toml").data)
    data["defaults"].update({"k7_per_k_v": 0.2, "k7": 0.001})
    with pytest.raises(ConfigError, match=r"k7.*either k7_per_k_v or k7, not both"):
        ControlConfig.from_mapping(data, info)
