"""The independent plant family (servotau/experiments/plant_family.py) and its scorer (plant_scoring.py)."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from servotau.experiments import plant_family as pf
from servotau.experiments.plant_scoring import accepted, band_of, confusion, score

ROOT = Path(__file__).resolve().parents[1]
DUR = 6.0


@pytest.fixture(scope="module")
def family():
    """Seed 3's parameters, clean and with each effect alone, 6 s at a 1 ms record (one batch)."""
    hidden = [(), *[(e,) for e in pf.EFFECTS]]
    plants = [pf.draw_plant(3, hidden=h, period=2e-3, duration=DUR) for h in hidden]
    return {h[0] if h else "clean": (p, t) for h, p, t in zip(hidden, plants, pf.simulate(plants, DUR), strict=True)}


def _servo_residual(plant, true):
    """q_des - q - (tau / K + D / K dq) with the TRUE velocity and torque."""
    return true["q_des"] - true["q"] - (true["tau"] / plant.K + plant.D / plant.K * true["dq"])


def test_plant_code_is_independent_of_simulator_and_workbench():
    for name in ("plant_family.py",):
        tree = ast.parse((ROOT / "servotau" / "experiments" / name).read_text())
        mods = [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
        mods += [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
        assert not [m for m in mods if any(x in m for x in ("simrobot", "actuator", "identification"))]


@pytest.mark.parametrize("effect", ["clean", "backlash", "saturation", "thermal_drift", "stribeck"])
def test_a_plant_simulated_alone_is_its_batch_result_bit_for_bit(family, effect):
    """Alone, the simulation skips every term whose coefficient is zero; in the batch of every effect it computes
    them all. Both give the same signals, bit for bit (the skipped terms add exact zeros)."""
    plant, true = family[effect]
    (alone,) = pf.simulate([plant], DUR)
    for key, value in true.items():
        np.testing.assert_array_equal(alone[key], value, err_msg=key)


def test_clean_plant_obeys_the_two_term_model_exactly(family):
    plant, true = family["clean"]
    assert np.std(true["q_des"] - true["q"]) > 1e-4  # the servo error is not trivial
    assert np.sqrt(np.mean(_servo_residual(plant, true) ** 2)) < 1e-9


def test_clean_log_fits_to_quantisation_and_noise(family):
    plant, true = family["clean"]
    log = pf.measure(plant, true)
    step = int(round(plant.period / pf.RECORD))
    dq = true["dq"][::step]
    X = np.column_stack([log["tau"], dq])
    y = log["q_des"] - log["q"]
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    rms = np.sqrt(np.mean((y - X @ coef) ** 2))
    expected = np.sqrt(plant.res ** 2 / 12 + (plant.sigma / plant.K) ** 2)
    assert rms < 1.5 * expected
    assert coef[0] == pytest.approx(1 / plant.K, rel=0.1)


def test_sampling_and_quantisation_as_configured(family):
    plant, true = family["clean"]
    log = pf.measure(plant, true)
    assert set(log) == {"t", "q", "q_des", "tau"}
    assert np.allclose(np.diff(log["t"]), plant.period)
    assert np.allclose(np.round(log["q"] / plant.res) * plant.res, log["q"])
    noise = log["tau"] - true["tau"][::2]
    assert np.std(noise) == pytest.approx(plant.sigma, rel=0.15)


@pytest.mark.parametrize("seed", range(12))
def test_parameter_ranges(seed):
    p = pf.draw_plant(seed)
    assert 200 <= p.K <= 5000 and 0.02 <= p.J <= 0.5 and 1 <= 1e3 * p.period <= 16
    assert p.truth()["hidden"] == list(p.hidden)


def test_every_bench_plant_stays_bounded():
    """Seeds 0..99 as bench/workbench_family.py draws them (20 s commands, hidden effects from the seed), first 4 s.

    A stable servo's error is its torque over its stiffness (< 0.3 rad in this family); one whose torque limit
    cannot hold the gravity load lets the link sag toward hanging, still within half a turn. An unstable loop
    (seed 3 before the motor lag was clipped) passes 500 rad within these 4 s.
    """
    plants = [pf.draw_plant(seed) for seed in range(100)]
    error = np.array([np.max(np.abs(t["q"] - t["q_des"])) for t in pf.simulate(plants, 4.0)])
    assert np.all(error < np.pi), {p.seed: float(e) for p, e in zip(plants, error, strict=True) if not e < np.pi}


def test_motor_lag_keeps_the_servo_loop_damped():
    """The loop J T s^3 + J s^2 + D s + K of every drawn motor lag has its poles damped (ratio > 0.07)."""
    for seed in range(2000):
        p = pf.draw_plant(seed, hidden=("motor_lag",), duration=1.0)
        poles = np.roots([p.J * p.effect["motor_lag"]["T"], p.J, p.D, p.K])
        assert np.min(-poles.real / np.abs(poles)) > 0.07, (seed, p.effect)


def test_coulomb_is_a_step_at_zero_velocity(family):
    plant, true = family["coulomb"]
    r = _servo_residual(plant, true)
    moving = np.abs(true["dq"]) > 0.05
    fc = plant.effect["coulomb"]["fc"]
    assert np.median(r[moving & (true["dq"] > 0)]) == pytest.approx(fc / plant.K, rel=0.05)
    assert np.median(r[moving & (true["dq"] < 0)]) == pytest.approx(-fc / plant.K, rel=0.05)


def test_asymmetric_coulomb_differs_by_direction(family):
    plant, true = family["coulomb_asym"]
    r = _servo_residual(plant, true)
    p = plant.effect["coulomb_asym"]
    assert np.median(r[true["dq"] > 0.05]) == pytest.approx(p["fc_pos"] / plant.K, rel=0.05)
    assert np.median(r[true["dq"] < -0.05]) == pytest.approx(p["fc_neg"] / plant.K, rel=0.05)


def test_cogging_is_periodic_in_position(family):
    plant, true = family["cogging"]
    p = plant.effect["cogging"]
    expected = p["amp"] * np.sin(2 * np.pi * true["q"] / p["period"] + p["phase"]) / plant.K
    assert np.allclose(_servo_residual(plant, true), expected, atol=1e-3 * p["amp"] / plant.K)


@pytest.mark.parametrize("effect", ["stribeck", "viscous_power", "load_friction", "deadzone", "motor_lag",
                                    "delay", "thermal_drift", "backlash"])
def test_each_effect_leaves_a_servo_residual(family, effect):
    plant, true = family[effect]
    assert np.sqrt(np.mean(_servo_residual(plant, true) ** 2)) > 1e-6


def test_saturation_clips_the_motor_torque(family):
    plant, true = family["saturation"]
    tau_max = plant.effect["saturation"]["fraction"] * plant.tau_scale
    assert np.max(np.abs(true["tau_m"])) <= tau_max + 1e-9


def test_delay_shifts_the_command(family):
    plant, true = family["delay"]
    d = plant.effect["delay"]["d"]
    shifted = np.interp(true["t"] - d, true["t"], true["q_des"])
    r = shifted - true["q"] - (true["tau"] / plant.K + plant.D / plant.K * true["dq"])
    assert np.sqrt(np.mean(r[50:] ** 2)) < 0.05 * np.sqrt(np.mean(_servo_residual(plant, true)[50:] ** 2))


def test_csv_has_the_workbench_columns(tmp_path, family):
    plant, true = family["clean"]
    path = tmp_path / "log.csv"
    pf.write_csv(pf.measure(plant, true), path)
    assert path.read_text().splitlines()[0] == "t,q,q_des,tau"


def _row(seed, hidden, verdict, ranked, period=1):
    return {"seed": seed, "part": "tuning" if seed < 50 else "held_out", "period_ms": period,
            "band": band_of(period), "hidden": hidden, "verdict": verdict, "ranked": ranked, "gains": [],
            "seconds": 0.0}


def test_scorer_on_a_hand_made_table():
    rows = [
        _row(0, [], "missing_effect", ["delay", "motor_lag"]),          # false alarm
        _row(1, [], "no_missing_effect", ["delay", "motor_lag"]),       # no alarm
        _row(2, ["coulomb"], "missing_effect", ["coulomb", "stribeck"]),  # top 1, named
        _row(3, ["coulomb"], "missing_effect", ["stribeck", "coulomb"], period=8),  # top 2 only
        _row(4, ["cogging", "delay"], "no_missing_effect", ["delay", "x"]),  # delay top 1, not named
        _row(60, ["viscous_power"], "missing_effect", ["viscous_power_law", "coulomb"]),
    ]
    s = score(rows)
    t = s["tuning"]
    assert t["clean"] == {"n": 2, "false_alarm": 0.5, "unexplained": 0.0, "errors": 0}
    assert t["effects"]["coulomb"] == {"n": 2, "top1": 0.5, "top2": 1.0, "named": 0.5, "steps2": 0.5}
    assert t["effects"]["delay"] == {"n": 1, "top1": 1.0, "top2": 1.0, "named": 0.0, "steps2": 0.0}
    assert t["effects"]["cogging"]["top2"] == 0.0
    assert t["top2"] == 0.75
    assert t["bands"]["7-16 ms"]["effects"]["coulomb"]["top1"] == 0.0
    assert t["confusion"]["none"] == {"delay": 1, "no_missing_effect": 1}
    assert t["confusion"]["cogging"] == {"no_missing_effect": 1}
    assert s["held_out"]["effects"]["viscous_power"]["top1"] == 1.0
    assert confusion(rows)["coulomb"] == {"coulomb": 1, "stribeck": 1}
    assert accepted("coulomb", "coulomb") and not accepted("coulomb", "coulomb_asym") and not accepted("delay", None)
