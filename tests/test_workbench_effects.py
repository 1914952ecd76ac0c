"""The workbench on data with hidden effects of the simulated HRP-2 knee (identification/workbench/).

Each hidden effect of the simulator, alone and in pairs, with realistic corruption (quantised encoder,
velocity by centred Savitzky-Golay differentiation, torque estimate delayed 2 ms with 0.3 N m of noise):
the injected effect must rank first (top two for a documented confusable pair) and adding it must halve
the held-out error. Misses are measured and marked ``xfail(strict=True)`` with the number: the bar is not
lowered, and a miss that starts passing fails the suite so that the mark is removed.
"""

import itertools
import json

import numpy as np
import pytest
from support.workbench_cases import (
    CACHE_DIR,
    PAIRS,
    SINGLE,
    SLOW_CASES,
    outcome,
    run_pairs,
    sim_dataset,
    sim_log,
)

from servotau.identification.workbench import MIN_GAIN, get_effect
from servotau.simrobot.servo_config import EFFECT_PARAMS

BAR = 0.5  # the held-out error must fall by at least half

# Measured on this simulator and excitation (docs/workbench.md, "Results"): why they miss. None misses now:
# saturation (the last one) passes since its term integrates the command's lead past the limit, on a log
# that reaches the limit while moving in every cycle.
RANK_MISSES: dict[str, str] = {}
FALL_MISSES: dict[str, str] = {}


def _param(effect, misses=()):
    """``effect`` as a parameter: xfail where a documented miss, slow where its case is (SLOW_CASES)."""
    marks = [pytest.mark.slow] if effect in SLOW_CASES else []
    if effect in misses:
        marks.append(pytest.mark.xfail(strict=True, reason=misses[effect]))
    return pytest.param(effect, marks=marks)


def _confusable(a: str, b: str) -> bool:
    return b in get_effect(a).confusable or a in get_effect(b).confusable


def test_logs_are_what_a_controller_logs():
    """The clean log has the single-joint columns, a quantised encoder and no velocity column."""
    cols = sim_log("clean")
    assert {"t", "q", "q_des", "tau", "segment"} <= set(cols) and "dq" not in cols
    res = 1e-5  # [rad] encoder resolution of config/sensors.toml
    assert np.allclose(np.round(cols["q"] / res) * res, cols["q"], atol=1e-12)
    assert len(np.unique(cols["segment"])) == 4
    ds = sim_dataset("clean")
    assert ds.n == len(cols["t"]) and any("Savitzky-Golay" in n for n in ds.notes)
    assert np.corrcoef(ds.signals["dq"], cols["true/dq"])[0, 1] > 0.999


def test_excitation_covers_every_quadrant_and_reversals():
    """The excitation cycle reverses often, holds still and moves loaded in all four quadrants."""
    from servotau.identification.workbench import excitation_report

    e = excitation_report(sim_dataset("clean").signals)
    assert e.velocity_reversals >= 12 and e.hold_time > 2.0 and e.fast_time > 1.0
    assert min(e.quadrants.values()) > 0.1 and e.torque_reversals_at_rest >= 4


@pytest.mark.parametrize("effect", [_param(e, RANK_MISSES) for e in SINGLE])
def test_hidden_effect_ranks_first(effect):
    """The injected effect ranks first, or second behind a documented confusable effect."""
    o = outcome(effect)
    assert o["verdict"] == "missing_effect", o["message"]
    assert o["rank"] == 1 or (o["rank"] == 2 and _confusable(effect, o["top"])), (o["rank"], o["ranking"][:3])
    assert o["gain"] >= MIN_GAIN and o["consistent"]


@pytest.mark.parametrize("effect", [_param(e, FALL_MISSES) for e in SINGLE])
def test_adding_the_effect_halves_the_heldout_error(effect):
    """Adding the injected effect (shapes refitted) removes at least half of the held-out error."""
    o = outcome(effect)
    assert o["fall"] >= BAR, f"fall {o['fall']:.3f}"


def test_no_false_alarm_on_the_default_servo():
    """On data without hidden effect, the reference model of the default servo misses nothing."""
    o = outcome("clean")
    assert o["verdict"] == "no_missing_effect", o["message"]
    assert all(g < MIN_GAIN for _, g in o["ranking"])
    assert o["probes"]["memory"] < MIN_GAIN, o["probes"]  # the residual's own past: 5.7 % measured


def test_the_dead_zone_is_found_in_its_crossing_form_with_the_simulators_width():
    """The 3 mrad dead band on the position error is named in its crossing form (inside the band the joint is
    free and its error follows the command's lead from the edge it entered at), with a half-width within 20 %
    of the simulator's (3.36 mrad measured); with it nothing is missing (fall 0.96 measured)."""
    o = outcome("deadzone")
    width = EFFECT_PARAMS["deadzone"]["e_deadzone"][0]  # [rad]
    assert o["shape"].get("crossing") == 1.0 and abs(o["shape"]["width"] - width) <= 0.2 * width, o["shape"]
    assert o["fall"] >= BAR
    assert o["final_verdict"] == "no_missing_effect", o["final_message"]


def test_the_default_servo_effects_are_found_from_the_papers_model():
    """From the paper's k_tau, k_v alone, the greedy ladder finds the default servo's dead zone and
    direction gain, and stops with nothing missing."""
    o = outcome("clean@paper")
    assert {"deadzone", "direction_gain"} <= set(o["added"]), o["added"]
    assert o["final_verdict"] in ("no_missing_effect", "unexplained"), o["final_message"]
    assert o["fall"] >= BAR


@pytest.mark.parametrize("pair", [_param("+".join(p)) for p in PAIRS])
def test_pairs_are_found_by_the_greedy_ladder(pair):
    """Two hidden effects together: the greedy ladder adds both, then finds nothing missing."""
    o = outcome(pair)
    assert set(pair.split("+")) <= set(o["added"]), (o["added"], o["ranks"])
    assert o["fall"] >= BAR
    assert o["final_verdict"] != "missing_effect", o["final_message"]


@pytest.mark.slow  # its two cases are in SLOW_CASES (the default suite's budget)
def test_out_of_grid_stribeck_on_the_simulator_is_partially_explained():
    """A Stribeck velocity outside the grid (0.6 rad/s, grid up to 0.32) is named at the largest v_s of the
    grid and reported as partially explained; the same excitation with v_s = 0.16 rad/s (in the grid) is not."""
    out, inside = outcome("stribeck@out_of_grid"), outcome("stribeck@in_grid")
    v_max = max(g["v_s"] for g in get_effect("stribeck").grid)
    assert out["verdict"] == "missing_effect" and out["top"] == "stribeck", out["message"]
    assert out["shape"]["v_s"] == v_max and out["partial"], (out["shape"], out["explained"], out["remaining"])
    assert "partially explained" in out["message"]
    assert inside["verdict"] == "missing_effect" and inside["top"] == "stribeck", inside["message"]
    assert inside["shape"]["v_s"] < v_max and not inside["partial"], (inside["shape"], inside["remaining"])


@pytest.mark.slow  # the two fast Stribeck cases are in SLOW_CASES
def test_fast_motion_without_a_current_limit_is_not_saturation():
    """The excitation of the saturation case without a limit (the fast Stribeck logs, 20 A): the saturation
    term, which integrates the error where the torque proxy is largest, stays below min_gain."""
    for name in ("stribeck@in_grid", "stribeck@out_of_grid"):
        gains = dict(outcome(name)["ranking"])
        assert gains["saturation"] < MIN_GAIN, (name, gains["saturation"])


@pytest.mark.slow
def test_a_link_side_angle_separates_backlash_from_elastic():
    """The documented experiment of the pair: with a link-side angle, the gear deflection of a gear with play
    steps by half the play at zero torque (named, coefficient within 25 % of it); an elastic gear's does not,
    and its slope against the torque is the gear compliance."""
    b, e = outcome("backlash@link"), outcome("elastic@link")
    half_play = EFFECT_PARAMS["backlash"]["backlash"][0] / 2.0  # [rad]
    assert b["step_testable"] and e["step_testable"]
    assert b["top"] == "deadzone" and b["step_gain"] >= MIN_GAIN, b["message"]
    assert abs(b["step"] - half_play) <= 0.25 * half_play, b["step"]
    assert e["step_gain"] < MIN_GAIN, e["ranking"][:3]
    gear_k = EFFECT_PARAMS["elastic"]["gear_k"][0]  # [N m/rad]
    assert abs(e["k_tau"] * gear_k - 1.0) < 0.05, e["k_tau"]


def test_confusable_runner_up_comes_with_the_separating_experiment():
    """When the runner-up is a documented confusable effect, the diagnosis names the experiment."""
    o = outcome("backlash")
    assert o["confusion"] is not None and set(o["confusion"]) == {"backlash", "elastic"}
    assert "link-side" in o["message"]


@pytest.mark.slow
def test_every_pair_of_hidden_effects():
    """All 55 pairs (``make experiments``): the greedy ladder's first step adds one of the two hidden effects
    (or a documented confusable one) in every pair (55/55 measured; logs hiding a current limit run the fast
    excitation, see ``EXCITATION_OF``), and the held-out error falls by at least half in every pair (the
    smallest fall measured: 0.53, Stribeck + thermal drift); the table is written for the report."""
    pairs = list(itertools.combinations(SINGLE, 2))
    results = run_pairs(pairs)
    CACHE_DIR.mkdir(parents=True, exist_ok=True)
    (CACHE_DIR / "pairs.json").write_text(json.dumps(results, indent=1, default=str))
    first_ok = [o for o, p in zip(results, pairs, strict=True)
                if o["added"] and (o["added"][0] in p or any(_confusable(o["added"][0], e) for e in p))]
    both = [o for o, p in zip(results, pairs, strict=True) if set(p) <= set(o["added"])]
    both_elastic = [o for o, p in zip(results, pairs, strict=True)
                    if all(e in o["added"] or (e == "backlash" and "elastic" in o["added"]) for e in p)]
    # an added effect that is neither hidden nor documented as confusable with a hidden one
    false = [(o["name"], a) for o, p in zip(results, pairs, strict=True) for a in o["added"]
             if a not in p and not any(_confusable(a, e) for e in p)]
    under = [(o["name"], round(o["fall"], 3), o["final_verdict"]) for o in results if o["fall"] < BAR]
    memory = [o["name"] for o in results if o["final_verdict"] == "unexplained" and "own past" in o["final_message"]]
    verdicts = {v: sum(o["final_verdict"] == v for o in results) for v in sorted({o["final_verdict"] for o in results})}
    print(f"\nfirst step right in {len(first_ok)}/{len(pairs)} pairs, both added in {len(both)}/{len(pairs)} "
          f"({len(both_elastic)} counting elastic for backlash), {len(false)} false additions: {false}")
    print(f"smallest fall {min(o['fall'] for o in results):.3f}; fall under {BAR}: {under}; final verdicts "
          f"{verdicts}, {len(memory)} unexplained by the memory probe: {memory}")
    assert len(first_ok) == len(pairs), [o["name"] for o in results if o not in first_ok]
    assert not under, under
