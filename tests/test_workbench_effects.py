"""The workbench on data with hidden effects of the simulated HRP-2 knee (identification/workbench/).

Each hidden effect of the simulator, alone and in pairs, with realistic corruption (quantised encoder,
velocity by centred Savitzky-Golay differentiation, torque estimate delayed 2 ms with 0.3 N m of noise):
the injected effect must rank first (top two for a documented confusable pair) and adding it must halve
the held-out error. Misses are measured and marked ``xfail(strict=True)`` with the number: the bar is not
lowered, and a miss that starts passing fails the suite so that the mark is removed.
"""

import itertools
import json

import pytest
from test_workbench_cases import _CACHE_DIR, PAIRS, SINGLE, outcome, run_pairs

from servotau.identification.workbench import MIN_GAIN, get_effect

BAR = 0.5  # the held-out error must fall by at least half

# Measured on this simulator and excitation (docs/workbench.md, "Results"): why they miss.
RANK_MISSES = {
    "saturation": "past the current limit the error is not a function of torque and velocity: the indicator "
                  "term ranks first but removes 4 % (< min_gain); the verdict is 'unexplained', at the largest effort",
}
FALL_MISSES = {
    "deadzone": "inside a 3 mrad position dead band the error is undetermined (the joint drifts): fall 0.49",
    "backlash": "motor-side encoders: the play is invisible statically, only the rotor inertia shows: fall 0.48",
    "saturation": "see RANK_MISSES: fall -0.06",
}


def _param(effect, misses):
    if effect in misses:
        return pytest.param(effect, marks=pytest.mark.xfail(strict=True, reason=misses[effect]))
    return effect


def _confusable(a: str, b: str) -> bool:
    return b in get_effect(a).confusable or a in get_effect(b).confusable


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


def test_the_default_servo_effects_are_found_from_the_papers_model():
    """From the paper's k_tau, k_v alone, the greedy ladder finds the default servo's dead zone and
    direction gain, and stops with nothing missing."""
    o = outcome("clean@paper")
    assert {"deadzone", "direction_gain"} <= set(o["added"]), o["added"]
    assert o["final_verdict"] in ("no_missing_effect", "unexplained"), o["final_message"]
    assert o["fall"] >= BAR


@pytest.mark.parametrize("pair", PAIRS, ids=["+".join(p) for p in PAIRS])
def test_pairs_are_found_by_the_greedy_ladder(pair):
    """Two hidden effects together: the greedy ladder adds both, then finds nothing missing."""
    o = outcome("+".join(pair))
    assert set(pair) <= set(o["added"]), (o["added"], o["ranks"])
    assert o["fall"] >= BAR
    assert o["final_verdict"] != "missing_effect", o["final_message"]


def test_confusable_runner_up_comes_with_the_separating_experiment():
    """When the runner-up is a documented confusable effect, the diagnosis names the experiment."""
    o = outcome("backlash")
    assert o["confusion"] is not None and set(o["confusion"]) == {"backlash", "elastic"}
    assert "link-side" in o["message"]


@pytest.mark.slow
def test_every_pair_of_hidden_effects():
    """All 55 pairs (``make experiments``): the greedy ladder's first step adds one of the two hidden effects
    (or a documented confusable one) in most pairs; the table is written for the report."""
    pairs = list(itertools.combinations(SINGLE, 2))
    results = run_pairs(pairs)
    _CACHE_DIR.mkdir(parents=True, exist_ok=True)
    (_CACHE_DIR / "pairs.json").write_text(json.dumps(results, indent=1, default=str))
    first_ok = [o for o, p in zip(results, pairs, strict=True)
                if o["added"] and (o["added"][0] in p or any(_confusable(o["added"][0], e) for e in p))]
    both = [o for o, p in zip(results, pairs, strict=True) if set(p) <= set(o["added"])]
    print(f"\nfirst step right in {len(first_ok)}/{len(pairs)} pairs, both added in {len(both)}/{len(pairs)}")
    assert len(first_ok) >= 0.8 * len(pairs)
