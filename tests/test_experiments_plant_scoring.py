"""Oracle detectability of the plant family's hidden effects (plant_oracle.py) and its scores (plant_scoring.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from servotau.experiments import plant_family as pf
from servotau.experiments import plant_scoring as ps
from servotau.experiments.plant_oracle import alone, effect_residuals, oracle_gain, servo_residual
from servotau.experiments.plant_scoring import band_of, confusion, detectable, part_of, score
from servotau.identification.workbench import MIN_GAIN, load_dataset

DUR = 2.0  # [s]


def test_residual_is_zero_on_clean_plants():
    plants = [pf.draw_plant(s, hidden=(), period=2e-3, duration=DUR) for s in (1, 7, 21, 64)]
    for p, tr in zip(plants, pf.simulate(plants, DUR), strict=True):
        assert np.std(tr["q_des"] - tr["q"]) > 1e-5  # the servo error is not trivial
        assert np.sqrt(np.mean(servo_residual(p, tr) ** 2)) < 1e-10


def test_residual_carries_the_delayed_command_and_the_thermal_offset():
    plants = [pf.draw_plant(4, hidden=(e,), period=2e-3, duration=DUR) for e in ("delay", "thermal_drift")]
    (pd, td), (pt, tt) = zip(plants, pf.simulate(plants, DUR), strict=True)
    d = pd.effect["delay"]["d"]
    command_shift = td["q_des"] - np.interp(td["t"] - d, td["t"], td["q_des"])
    assert np.sqrt(np.mean((servo_residual(pd, td) - command_shift)[50:] ** 2)) < 0.05 * np.std(command_shift)
    # the torque constant drops with the heat H (the servo's command scaled by 1 - a H: the damping's part is
    # measured as velocity, only the torque's part scales), and the logged torque carries the offset: r has both
    drop = pt.effect["thermal_drift"]["gain_drop"] * tt["heat"]
    gain_part = tt["tau"] / pt.K * (1 / (1 - drop) - 1)
    miss = servo_residual(pt, tt) - gain_part
    assert np.sqrt(np.mean((miss + tt["thermal_offset"] / pt.K) ** 2)) < 0.01 * np.sqrt(np.mean(miss ** 2))


def test_oracle_gain_is_large_for_a_big_coulomb_friction_and_small_for_a_tiny_one():
    p = pf.draw_plant(11, hidden=("coulomb",), period=2e-3, duration=DUR)
    big = replace(p, effect={"coulomb": {"fc": 0.1 * p.tau_scale}})
    tiny = replace(p, effect={"coulomb": {"fc": 1e-4 * p.tau_scale}})
    gains = []
    for plant, tr, res in zip((big, tiny), trues := pf.simulate([big, tiny], DUR),
                              effect_residuals([big, tiny], trues), strict=True):
        ds = load_dataset(dict(pf.measure(plant, tr)))
        gains.append(oracle_gain(ds, tr["t"], res["coulomb"]))
    assert gains[0] > 0.5
    assert gains[1] < MIN_GAIN


def test_each_effect_of_a_pair_gets_its_own_oracle():
    p = pf.draw_plant(11, hidden=("cogging", "coulomb"), period=2e-3, duration=DUR)
    p = replace(p, effect={"coulomb": {"fc": 0.1 * p.tau_scale},
                           "cogging": {"amp": 1e-4 * p.tau_scale, "period": 0.1, "phase": 0.0}})
    assert alone(p, "coulomb").effect == {"coulomb": p.effect["coulomb"]} and alone(p, "coulomb").command == p.command
    (tr,) = pf.simulate([p], DUR)
    (res,) = effect_residuals([p], [tr])
    assert set(res) == {"all", "coulomb", "cogging"} and len(res["coulomb"]) == 2
    ds = load_dataset(dict(pf.measure(p, tr)))
    assert oracle_gain(ds, tr["t"], res["coulomb"]) > 0.5
    assert oracle_gain(ds, tr["t"], res["cogging"]) < MIN_GAIN


def _row(seed, hidden, verdict, ranked, oracle):
    return {"seed": seed, "part": part_of(seed), "period_ms": 1, "band": band_of(1),
            "hidden": hidden, "verdict": verdict, "ranked": ranked, "gains": [0.0, 0.0], "seconds": 0.0,
            **({"oracle_gain": oracle} if oracle is not None else {})}


def test_scores_on_the_detectable_effects():
    rows = [
        _row(0, ["coulomb"], "missing_effect", ["coulomb", "stribeck"], {"coulomb": 0.8}),  # detectable, hit
        _row(1, ["coulomb"], "no_missing_effect", ["stribeck", "delay"], {"coulomb": 0.02}),  # undetectable miss
        _row(2, ["delay"], "no_missing_effect", ["stribeck", "coulomb"], {"delay": 0.3}),  # detectable miss
        _row(3, ["cogging", "delay"], "missing_effect", ["delay", "x"], {"cogging": 0.05, "delay": 0.5}),
        _row(4, ["backlash"], "missing_effect", ["delay", "x"], None),  # no oracle: unknown
        _row(5, [], "missing_effect", ["delay", "x"], None),  # clean: not in the section
    ]
    d = detectable(rows, 0.1)
    assert (d["n"], d["undetectable"], d["unknown"]) == (3, 2, 1)
    assert d["top1"] == pytest.approx(2 / 3, abs=1e-3) and d["named"] == pytest.approx(2 / 3, abs=1e-3)
    assert d["effects"]["coulomb"] == {"n": 1, "top1": 1.0, "top2": 1.0, "named": 1.0, "steps2": 1.0,
                                       "undetectable": 1, "unknown": 0}
    assert [(m["seed"], m["effect"], m["oracle_gain"]) for m in d["misses"]] == [(2, "delay", 0.3)]
    assert d["n_misses"] == 1
    s = score(rows, min_gain=0.1)
    assert s["tuning"]["detectable"]["n"] == 3
    assert s["tuning"]["top1"] == 0.333  # the raw scores still count every hidden effect (2 hits of 6)
    assert score(rows)["tuning"]["detectable"]["min_gain"] == MIN_GAIN


def test_named_is_what_the_verdict_names_not_the_first_ranked():
    """A first-ranked effect that failed in too many blocks is not named: the row's ``named`` is scored."""
    row = {"seed": 0, "part": "tuning", "period_ms": 1, "band": "1-2 ms", "hidden": ["coulomb"],
           "verdict": "missing_effect", "named": "coulomb", "ranked": ["delay", "coulomb"], "gains": [0.3, 0.2]}
    s = score([row])["tuning"]
    assert s["top1"] == 0.0 and s["top2"] == 1.0 and s["named"] == 1.0
    assert confusion([row]) == {"coulomb": {"coulomb": 1}}


def test_the_parts_are_fixed_seed_ranges():
    assert [part_of(s) for s in (0, 49, 50, 99, 100, 149, 999, 1000)] == [
        "tuning", "tuning", "held_out", "held_out", "unseen", "unseen", "unseen", "tests"]


def test_the_unseen_part_is_scored_but_never_shown_per_seed():
    """Rows of seeds from 100 (made up here: no unseen plant is simulated): scored in their own part, their misses
    counted, not listed."""
    rows = [_row(2, ["delay"], "no_missing_effect", ["stribeck", "coulomb"], {"delay": 0.3}),
            _row(120, ["delay"], "no_missing_effect", ["stribeck", "coulomb"], {"delay": 0.3}),
            _row(121, ["coulomb"], "missing_effect", ["coulomb", "stribeck"], {"coulomb": 0.8})]
    s = score(rows, min_gain=0.1)
    assert set(s) == {"tuning", "held_out", "unseen"} and "unseen" not in score(rows[:1], min_gain=0.1)
    unseen = s["unseen"]["detectable"]
    assert (unseen["n"], unseen["n_misses"], unseen["misses"]) == (2, 1, [])
    assert [m["seed"] for m in detectable(rows, 0.1)["misses"]] == [2]
    assert ps.reveal(rows[0]) and not ps.reveal(rows[1])


def test_run_family_reports_unseen_logs_as_a_counter(monkeypatch):
    """The progress lines name each tuning or held-out log and only count the unseen ones (fake batches and jobs:
    no plant is simulated)."""
    seeds = [48, 49, 100, 101, 102]
    monkeypatch.setattr(ps, "BATCH", 2)
    monkeypatch.setattr(ps, "_batch", lambda plants, duration, pool: [p.seed for p in plants])
    monkeypatch.setattr(ps, "draw_plant", lambda seed, duration: type("P", (), {"seed": seed})())
    monkeypatch.setattr(ps, "_job", lambda seed: ({"seed": seed, "period_ms": 3, "hidden": ["delay"]},
                                                  {"verdict": "unexplained", "ranked": ["x"], "gains": [0.1]}))
    lines: list[str] = []
    rows = ps.run_family(seeds, workers=1, progress=lines.append)
    assert [r["part"] for r in rows] == ["tuning", "tuning", "unseen", "unseen", "unseen"]
    shown = [x for x in lines if not x.startswith("simulating")]
    assert shown[2:] == ["unseen: 1/3 done", "unseen: 2/3 done", "unseen: 3/3 done"]
    assert all("seed  10" not in x and "unexplained" not in x for x in shown[2:])
    assert shown[0].startswith("seed   48  3 ms hidden ['delay']: unexplained")


def test_steps2_counts_the_next_effect_to_add():
    """A pair whose second effect ranks below the first one's look-alikes but is the next to add once the first is
    in the model (``then``): found in two steps, not in the top two."""
    row = {"seed": 0, "part": "tuning", "period_ms": 1, "band": "1-2 ms", "hidden": ["coulomb", "cogging"],
           "verdict": "missing_effect", "named": "coulomb", "then": "cogging", "ranked": ["coulomb", "stribeck"],
           "gains": [0.5, 0.4]}
    s = score([row])["tuning"]
    assert s["top2"] == 0.5 and s["steps2"] == 1.0
    assert s["effects"]["cogging"]["steps2"] == 1.0 and s["effects"]["cogging"]["top2"] == 0.0
