"""Tests of the servo family's draws (servotau/experiments/servo_family.py): ranges, determinism, a servo file the
simulator reads with config/servo.toml's field names."""

import numpy as np
import pytest

from servotau.config import CONFIG_DIR, load_toml
from servotau.description import JOINT_NAMES
from servotau.experiments.servo_family import RANGES, draw, score, write_servo_file
from servotau.simrobot.servo_config import check_servo_file


def test_draws_are_deterministic_per_seed_and_inside_their_ranges():
    a, b, c = draw(3), draw(3), draw(4)
    assert a.groups == b.groups and a.groups != c.groups
    for g in a.groups.values():
        for f, (_, lo, hi) in RANGES.items():
            assert lo <= g[f] <= hi


def test_servo_file_scales_the_nominal_groups_and_loads(tmp_path):
    d = draw(7)
    path = write_servo_file(d, tmp_path / "servo.toml")
    params = check_servo_file(path, JOINT_NAMES)
    nominal = load_toml(CONFIG_DIR / "servo.toml").section("groups").section("knee").data
    knee = JOINT_NAMES.index("RLEG_JOINT3")
    f = d.groups["knee"]
    assert params.kp[knee] == pytest.approx(nominal["kp"] * f["kp"])
    assert params.kd[knee] == pytest.approx(nominal["kd"] * f["damping"])
    assert params.b[knee] == pytest.approx(nominal["b"] * f["damping"])
    assert params.tau_c[knee] == pytest.approx(nominal["tau_c"] * f["tau_c"])
    assert params.i_deadzone[knee] == pytest.approx(f["i_deadzone"])
    assert params.i_max[knee] == pytest.approx(f["i_max"])
    assert np.all(params.kp > 0)


def test_score_counts_wins_of_tripped_runs_as_losses():
    row = {"seed": 1, "tripped": {"K6=1": None, "K6=0.5": "trip"},
           "wins": {"K6=1": {"knee": {"mean": True, "max": False}}, "K6=0.5": {"knee": {"mean": False, "max": False}}}}
    s = score([row], (1.0, 0.5))
    assert s["K6=1"] == {"wins": 1, "cases": 2, "share": 0.5, "trips": []}
    assert s["K6=0.5"]["trips"] == [1]


def test_merged_parts_give_the_section_with_targets_met_or_missed():
    from servotau.experiments.servo_family import merge, section_markdown

    def row(seed, win, trip=None):
        return {"seed": seed, "identify_seconds": 10.0, "tripped": {"K6=1": trip},
                "max_mrad": {"position": [1.0] * 6, "K6=1": [0.5] * 6},
                "wins": {"K6=1": {j: {"mean": win, "max": win} for j in "abcdef"}}}

    a = {"k6": [1.0], "effects": ["deadzone"], "max_steps": 1, "seconds": 5.0,
         "draws": {"tuning": [row(0, True)], "held_out": []}}
    b = {**a, "draws": {"tuning": [], "held_out": [row(1000, False, "trip")]}}
    m = merge([a, b])
    assert m["parts"]["tuning"]["K6=1"]["share"] == 1.0 and m["parts"]["held_out"]["K6=1"]["trips"] == [1000]
    assert m["all"]["K6=1"] == {"wins": 12, "cases": 24, "share": 0.5, "trips": [1000]}
    text = section_markdown(m, {"k_p": 0.5, "k7_per_k_v": 0.15, "k_iq": 2.0})
    assert "| all | 2 | 12/24 = 50 %, TRIP seeds [1000] |" in text and "K6=1 MISSED" in text
