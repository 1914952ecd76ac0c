"""Preprocessing that adapts to the data (issue 18, item 1): windows chosen by cross-validation, the log's own
velocity, and no lag-like false alarm on a clean log of a stiff plant (servotau/experiments/plant_family.py)."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from support.synthetic import two_sine_log

from servotau.identification.workbench import diagnose, load_dataset, parse_spec


def test_log_velocity_used_when_present_and_said():
    cols = two_sine_log(1e-3, 1e-5, with_dq=True)
    ds = load_dataset(cols)
    assert np.array_equal(ds.signals["dq"], cols["dq"])
    assert any("log's own velocity column 'dq'" in n for n in ds.notes)


def test_notes_give_windows_in_samples_and_seconds():
    ds = load_dataset(two_sine_log(2e-3, 1e-5))
    dq_note = next(n for n in ds.notes if n.startswith("dq:"))
    tau_note = next(n for n in ds.notes if n.startswith("tau:"))
    assert "samples =" in dq_note and "ms" in dq_note and "cross-validation" in dq_note
    assert "samples =" in tau_note and "cross-validation" in tau_note


def test_time_jumps_are_noted():
    cols = two_sine_log(1e-3, 1e-5)
    cols["t"] = cols["t"].copy()
    cols["t"][2000:] += 0.05
    ds = load_dataset(cols)
    assert any(n.startswith("time: 1 steps longer") for n in ds.notes)


@functools.cache
def _simulated(seed: int, hidden: tuple[str, ...], period: float | None = 1e-3):
    """A plant of the independent family and its true signals over 8 s, simulated once per test process (several
    tests read the same clean log; nothing here writes into the arrays)."""
    from servotau.experiments import plant_family as pf

    plant = pf.draw_plant(seed, hidden=hidden) if period is None else pf.draw_plant(seed, hidden=hidden,
                                                                                     period=period, duration=8.0)
    (true,) = pf.simulate([plant], 8.0)
    return plant, true


def _plant_diagnosis(seed, hidden, **load):
    from servotau.experiments import plant_family as pf

    plant, true = _simulated(seed, hidden)
    ds = load_dataset(dict(pf.measure(plant, true)), **load)
    return plant, ds, diagnose(ds, parse_spec("paper", ds.signals))


def test_clean_stiff_plant_raises_no_lag_false_alarm():
    plant, ds, d = _plant_diagnosis(6, ())
    assert plant.K > 2000  # a stiff servo: the fixed 41 ms window named `delay` here
    assert d.verdict != "missing_effect"
    assert ds.preprocessing["dq"]["source"] == "derivative of q" and ds.preprocessing["dq"]["window"] < 41


def test_lag_that_does_not_survive_a_less_biased_derivative_is_not_named():
    # clean; with an order-2 derivative over its chosen window `delay` removes ~20 % (the chosen order, 4, leaves it
    # no candidate: test_the_chosen_derivative_order_follows_the_motion_better)
    _plant, _ds, d = _plant_diagnosis(0, (), dq_order=2)
    assert d.verdict != "missing_effect"
    reasons = {c.effect: c.reason for c in d.ranking if not c.testable}
    assert "differentiation's error" in reasons["delay"]


def test_the_faster_derivative_check_runs_on_a_joined_log():
    """The clean log of the lag test above, cut in two recordings and joined (``model diagnose a.csv b.csv``): each
    half chooses its own window (order 2, as the test above), the check differentiates each with half of it, and
    `delay` is not named (without the check it was, at 19 %)."""
    from servotau.experiments import plant_family as pf
    from servotau.identification.workbench.checks import faster_derivative
    from servotau.identification.workbench.recordings import combine

    plant, true = _simulated(0, ())
    log = pf.measure(plant, true)
    half = len(log["t"]) // 2
    ds = combine([load_dataset({k: v[:half] for k, v in log.items()}, dq_order=2),
                  load_dataset({k: v[half:] for k, v in log.items()}, dq_order=2)])
    assert len(ds.preprocessing["dq"]["windows"]) == 2 and faster_derivative(ds) is not None
    d = diagnose(ds, parse_spec("paper", ds.signals))
    assert d.verdict != "missing_effect"
    reason = next(c.reason for c in d.ranking if c.effect == "delay")
    assert "differentiation's error" in reason and f"{ds.preprocessing['dq']['window']}" in reason


def test_the_chosen_derivative_order_follows_the_motion_better():
    """Clean logs of the independent plant family at 1-4 ms: the quartic's smoother predicts the held-out encoder
    samples better than the order-2 one by more than a standard error, so the quartic is chosen, and its velocity is
    closer to the plant's true velocity than the order-2 derivative over its own chosen window; `delay`, which stood
    in for the order-2 derivative's error on seed 0, is no candidate."""
    from servotau.experiments import plant_family as pf

    for seed, period in ((0, 1e-3), (2401, None), (2634, None)):
        plant, true = _simulated(seed, (), period)
        log = dict(pf.measure(plant, true))
        dq = true["dq"][:: int(round(plant.period / pf.RECORD))]
        ds, ds2 = load_dataset(log), load_dataset(log, dq_order=2)
        assert ds.preprocessing["dq"]["order"] == 4 and ds2.preprocessing["dq"]["order"] == 2
        err = [np.sqrt(np.mean((d.signals["dq"] - dq)[20:-20] ** 2)) for d in (ds, ds2)]
        assert err[0] < 0.5 * err[1], seed
    _plant, _ds, d = _plant_diagnosis(0, ())
    assert d.verdict == "no_missing_effect"
    assert next(c for c in d.ranking if c.effect == "delay").heldout_gain < 0.05


def test_true_delay_survives_the_less_biased_derivatives():
    _plant, _ds, d = _plant_diagnosis(3, ("delay",))
    assert d.verdict == "missing_effect" and d.ranking[0].effect == "delay"


FRICTION_HIDDEN = ((), ("coulomb",), ("stribeck",))


@pytest.fixture(scope="module")
def seed_2542():
    """Plant family seed 2542 clean, with Coulomb and with Stribeck friction: hidden -> (plant, true signals),
    simulated side by side (a plant of a batch is the plant simulated alone, bit for bit:
    test_experiments_plant_family)."""
    from servotau.experiments import plant_family as pf

    plants = [pf.draw_plant(2542, hidden=h) for h in FRICTION_HIDDEN]
    return dict(zip(FRICTION_HIDDEN, zip(plants, pf.simulate(plants), strict=True), strict=True))


@pytest.mark.parametrize("hidden", FRICTION_HIDDEN)
def test_friction_the_order_2_derivative_fakes_is_not_named_and_true_friction_is(hidden, seed_2542):
    """Plant family seed 2542 (10 ms; on the clean log dq by the order-2 derivative over 7 samples). Clean, a
    smoothed sign of dq fits the derivative's amplitude error (coulomb 16 % of the held-out error, 0.06 % with the
    cubic over the same samples): coulomb is untestable for the differentiation's error and nothing is named. The
    same plant with Coulomb or Stribeck friction hidden keeps it named: true friction survives the checks."""
    from servotau.experiments import plant_family as pf

    plant, true = seed_2542[hidden]
    ds = load_dataset(dict(pf.measure(plant, true)))
    d = diagnose(ds, parse_spec("paper", ds.signals))
    if hidden:
        assert d.verdict == "missing_effect" and d.top.effect == hidden[0], d.message
        return
    assert ds.preprocessing["dq"]["order"] == 2 and ds.preprocessing["dq"]["window"] == 7
    assert d.verdict == "no_missing_effect", d.message
    assert "differentiation's error" in d.candidate("coulomb").reason


def test_log_velocity_skips_the_faster_derivative_check():
    cols = two_sine_log(1e-3, 1e-5, with_dq=True)
    ds = load_dataset(cols)
    assert ds.preprocessing["dq"] == {"source": "log", "column": "dq"}
    from servotau.identification.workbench.checks import faster_derivative

    assert faster_derivative(ds) is None


def test_faster_derivative_runs_when_the_window_is_already_five_samples():
    """At 7-16 ms the chosen window is often the shortest (5 samples): the check falls back to the central
    difference (3 samples) instead of not running."""
    from servotau.identification.workbench.checks import faster_derivative

    ds = load_dataset(two_sine_log(10e-3, 1e-5, duration=40.0), dq_window=5)
    fast = faster_derivative(ds)
    assert fast is not None and fast[1] == 3
    q, dt = ds.signals["q"], ds.dt
    assert np.allclose(fast[0].signals["dq"][5:-5], (q[6:-4] - q[4:-6]) / (2 * dt))


def test_the_cubic_check_is_less_biased_than_the_workbench_velocity_at_a_coarse_period():
    """At 9 ms a 5 Hz motion spans few samples: the order-2 derivative over the chosen window lags the true
    velocity's shape (its error grows with the third derivative); the cubic fit over the same window is closer."""
    from servotau.identification.workbench.checks import derivative_checks

    dt = 9e-3
    t = np.arange(0.0, 20.0, dt)
    q = 0.05 * np.sin(2 * np.pi * 5 * t) + 0.2 * np.sin(2 * np.pi * 0.5 * t)
    dq = 0.05 * 2 * np.pi * 5 * np.cos(2 * np.pi * 5 * t) + 0.2 * 2 * np.pi * 0.5 * np.cos(2 * np.pi * 0.5 * t)
    ds = load_dataset({"t": t, "q": q, "q_des": q, "tau": np.sin(t)}, dq_window=7)
    checks = dict((how, c) for c, how in derivative_checks(ds))
    assert set(checks) == {"dq over 5 samples instead of 7", "dq by a cubic fit over the same 7 samples"}
    inner = slice(10, -10)
    err = lambda x: np.sqrt(np.mean((x.signals["dq"][inner] - dq[inner]) ** 2))  # noqa: E731
    assert err(checks["dq by a cubic fit over the same 7 samples"]) < 0.3 * err(ds)


def test_the_torque_check_is_less_biased_than_a_long_order_2_smoothing():
    """A torque bending within the smoothing window (a 2 Hz sine smoothed over 69 samples of 6 ms): the order-2 fit over
    the window flattens its peaks, the quartic over the same window much less; a window under 11 samples gets no
    check (a quartic there hardly smooths)."""
    from servotau.identification.workbench.checks import smoothing_check

    dt = 6e-3
    t = np.arange(0.0, 20.0, dt)
    tau = 10 * np.sin(2 * np.pi * 2 * t)
    q = 0.2 * np.sin(2 * np.pi * 0.5 * t)
    ds = load_dataset({"t": t, "q": q, "q_des": q + 1e-4 * tau, "tau": tau}, smooth_torque_s=69 * dt)
    checked, how = smoothing_check(ds)
    assert how == "tau smoothed by a quartic fit over the same 69 samples"
    inner = slice(40, -40)
    err = lambda x: np.sqrt(np.mean((x.signals["tau"][inner] - tau[inner]) ** 2))  # noqa: E731
    assert err(checked) < 0.3 * err(ds)
    short = load_dataset({"t": t, "q": q, "q_des": q + 1e-4 * tau, "tau": tau}, smooth_torque_s=9 * dt)
    assert smoothing_check(short) is None
