"""Tests of the diagnosis on synthetic tables (identification/workbench/diagnose.py): fast, known truth."""

import numpy as np
import pytest
from scipy.signal import lfilter
from support.synthetic import K_C, K_TAU, K_V, cogging_truth, synthetic_table

from servotau.errors import IdentificationError
from servotau.identification import Loss
from servotau.identification.workbench import (
    MIN_GAIN,
    diagnose,
    effect_names,
    load_dataset,
    parse_spec,
    register_effect,
    unregister_effect,
)


def test_injected_cogging_ranks_first_and_is_named():
    """A position ripple hidden in the data is named, with its period, and removes most of the error."""
    ds = load_dataset(synthetic_table(cogging_truth))
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert d.verdict == "missing_effect" and d.top.effect == "cogging"
    assert d.top.shape["period"] == pytest.approx(0.08, rel=0.01) and d.top.heldout_gain > 0.8
    assert not d.top.partial


def test_clean_synthetic_data_give_no_missing_effect():
    """Data that follow the base model exactly (plus white noise) name nothing."""
    ds = load_dataset(synthetic_table())
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert d.verdict == "no_missing_effect", d.message
    assert all(c.heldout_gain < 0.1 for c in d.ranking if c.testable)
    assert d.probes["memory"] < MIN_GAIN, d.probes  # white encoder noise has no memory


def test_a_constant_error_is_reported_whatever_the_verdict():
    """A servo error 0.4 mrad off zero (an encoder's zero) that the model without an offset cannot fit: the message
    says how much an offset removes and to rerun with --offset on; with the offset in the model it says nothing."""
    ds = load_dataset(synthetic_table(lambda t, q, dq, tau: np.full_like(t, 4e-4)))
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    notes = [c for c in d.checks if c.startswith("a constant error")]
    assert len(notes) == 1 and "--offset on" in notes[0] and notes[0] in d.message, d.message
    gain = int(notes[0].split("removes ")[1].split(" %")[0])
    assert gain >= 100 * MIN_GAIN
    clean = diagnose(load_dataset(synthetic_table()), parse_spec("coulomb", ds.signals))
    assert not any(c.startswith("a constant error") for c in clean.checks), clean.message
    with_offset = diagnose(ds, parse_spec("coulomb", ds.signals, offset=True))
    assert not any(c.startswith("a constant error") for c in with_offset.checks), with_offset.message


def test_stribeck_velocity_outside_the_grid_is_partially_explained():
    """A Stribeck velocity above the grid (1 rad/s, grid max 0.32) is named but partially explained; the same
    Stribeck friction inside the grid (0.16 rad/s) is fully explained. Over this log's speeds the out-of-grid
    curve is concave like a power-law viscous friction: with ``viscous_power`` in the library it is named first
    (delta 0.8, 83 % against stribeck's 73 % measured), stribeck runner-up with the separating experiment."""
    def stribeck(v_s):
        return lambda t, q, dq, tau: 1e-3 * np.tanh(dq / 0.005) * np.exp(-((dq / v_s) ** 2))

    ds = load_dataset(synthetic_table(stribeck(1.0), noise=2e-6))
    full = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert {full.top.effect, full.runner_up.effect} == {"stribeck", "viscous_power"}, full.message
    assert full.confusion is not None and "to separate them" in full.message
    d = diagnose(ds, parse_spec("coulomb", ds.signals), effects=[n for n in effect_names() if n != "viscous_power"])
    assert d.verdict == "missing_effect" and d.top.effect == "stribeck", d.message
    assert d.top.partial and d.top.remaining > 0.1 and "partially explained" in d.message
    inside = load_dataset(synthetic_table(stribeck(0.16), noise=2e-6))
    d2 = diagnose(inside, parse_spec("coulomb", inside.signals))
    assert d2.top.effect == "stribeck" and not d2.top.partial, d2.message
    assert d2.top.shape["v_s"] == 0.16


def test_structure_no_effect_explains_is_unexplained():
    """A bump of the error at one torque level (no effect of the library) gives the verdict unexplained."""
    ds = load_dataset(synthetic_table(lambda t, q, dq, tau: 3e-4 * np.exp(-(((tau - 12.0) / 3.0) ** 2))))
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert d.verdict == "unexplained", d.message
    family = max((k for k in d.probes if k != "memory"), key=d.probes.get)  # memory: any smooth residual
    assert family in ("torque", "servo_error") and f"function of the {family} signals" in d.message, d.message


def test_a_residual_with_memory_no_effect_explains_is_unexplained():
    """An error with 50 ms of memory that no present signal gives (like the error inside a dead band crossed
    freely, which depends on where the joint entered): no effect and no function of the present signals removes
    20 %, the residual's own past does (the memory probe): unexplained. (White noise: the clean synthetic test.)"""
    from servotau.identification.workbench.verdict import PROBE_FACTOR

    rng = np.random.default_rng(1)
    a = np.exp(-1e-3 / 0.05)  # 50 ms at 1 kHz
    wander = 2e-4 * lfilter([np.sqrt(1 - a * a)], [1.0, -a], rng.standard_normal(12000))
    ds = load_dataset(synthetic_table(lambda t, q, dq, tau: wander))
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert d.verdict == "unexplained" and max(d.probes, key=d.probes.get) == "memory", d.message
    assert all(v < PROBE_FACTOR * MIN_GAIN for k, v in d.probes.items() if k != "memory"), d.probes
    assert "own past" in d.message


def test_user_effect_registered_without_editing_the_library():
    """A user effect (a function of the log columns) is ranked like a built-in one, and can be removed."""
    bump = lambda t, q, dq, tau: 3e-4 * np.exp(-(((tau - 12.0) / 3.0) ** 2))  # noqa: E731
    ds = load_dataset(synthetic_table(bump))
    register_effect("torque_bump", lambda s, centre, width: np.exp(-(((s["tau"] - centre) / width) ** 2)),
                    grid=[{"centre": c, "width": 3.0} for c in (0.0, 6.0, 12.0, 18.0)], signals=("tau",),
                    signature="residual against torque: a bump", family="torque")
    try:
        d = diagnose(ds, parse_spec("coulomb", ds.signals))
        assert d.top.effect == "torque_bump" and d.top.shape["centre"] == 12.0 and d.verdict == "missing_effect"
        with pytest.raises(IdentificationError, match="already registered"):
            register_effect("torque_bump", lambda s: s["tau"])
    finally:
        unregister_effect("torque_bump")
    assert "torque_bump" not in effect_names()


def test_unexcited_effect_is_untestable_not_absent():
    """Without velocity reversals, direction-dependent effects are reported untestable, with the reason."""
    ds = load_dataset(synthetic_table(reversals=False))
    d = diagnose(ds, parse_spec("paper", ds.signals), effects=["coulomb", "coulomb_asym", "cogging"])
    c = d.candidate("coulomb")
    assert not c.testable and "reversals" in c.reason
    assert d.to_dict()["untestable"]["coulomb"] == c.reason
    assert d.rank_of("coulomb") == 0


def test_asymmetric_loss_names_the_same_effect():
    """With the asymmetric loss of eq. 8 the ranking still puts the hidden ripple first."""
    ds = load_dataset(synthetic_table(cogging_truth, seconds=8.0))
    d = diagnose(ds, parse_spec("coulomb", ds.signals), Loss.asymmetric(10.0),
                 effects=["cogging", "stribeck", "coulomb_asym", "deadzone"])
    assert d.top.effect == "cogging" and d.verdict == "missing_effect"
    assert d.base.heldout.w == 10.0


def test_unknown_effect_and_bad_threshold_are_refused():
    """Unknown effect names and thresholds outside (0, 1) raise naming the field."""
    ds = load_dataset(synthetic_table(seconds=4.0))
    with pytest.raises(IdentificationError, match="unknown effect 'cogs'.*expected one of"):
        diagnose(ds, parse_spec("coulomb", ds.signals), effects=["cogs"])
    with pytest.raises(IdentificationError, match="unknown effect 'frobnicate'"):
        parse_spec("coulomb+frobnicate", ds.signals)
    with pytest.raises(IdentificationError, match="min_gain"):
        diagnose(ds, parse_spec("coulomb", ds.signals), min_gain=1.5)


def test_a_coefficient_outside_the_physical_range_is_not_chosen():
    """An effect whose physics allows only positive coefficients is not named for a ripple it fits with a
    negative one (that block keeps the base model: gain 0), and is named when the range admits it."""
    ds = load_dataset(synthetic_table(lambda t, q, dq, tau: -2e-4 * np.sin(2 * np.pi * q / 0.08)))
    ripple = lambda s: np.sin(2 * np.pi * s["q"] / 0.08)  # noqa: E731
    with pytest.raises(IdentificationError, match="coefficient_range"):
        register_effect("ripple_bad", ripple, coefficient_range=(1.0, 0.0))
    register_effect("ripple_positive", ripple, signals=("q",), coefficient_range=(0.0, 1.0))
    register_effect("ripple_negative", ripple, signals=("q",), coefficient_range=(-1.0, 0.0))
    try:
        d = diagnose(ds, parse_spec("coulomb", ds.signals), effects=["ripple_positive", "ripple_negative"])
        assert d.candidate("ripple_positive").heldout_gain == 0.0
        assert d.candidate("ripple_negative").heldout_gain > 0.9 and d.top.effect == "ripple_negative"
    finally:
        unregister_effect("ripple_positive")
        unregister_effect("ripple_negative")


def _heat(dq, tau, tau_th=10.0):
    """The thermal_drift term's heat proxy of the synthetic servo error ``u`` (the base model without noise)."""
    from servotau.actuator.signals import lowpass

    u = K_TAU * tau + K_V * dq + K_C * np.tanh(dq / 0.005)
    return lowpass((u / 1e-3) ** 2, tau_th, 1e-3, y0=0.0)


def test_thermal_drift_coefficient_is_at_most_zero():
    """Heat lowers the viscosity: a velocity slope that falls as the winding heats is named (coefficient < 0);
    one that grows (a memory correction of high effort, not a drift) is not chosen although it fits as well."""
    falls = load_dataset(synthetic_table(lambda t, q, dq, tau: -1e-4 * _heat(dq, tau) * dq))
    grows = load_dataset(synthetic_table(lambda t, q, dq, tau: 1e-4 * _heat(dq, tau) * dq))
    d = diagnose(falls, parse_spec("coulomb", falls.signals), effects=["thermal_drift"])
    assert d.top.effect == "thermal_drift" and d.top.heldout_gain > 0.5 and d.top.coefficient < 0, d.message
    assert d.top.shape["gain"] == 0.0  # the friction form
    from dataclasses import replace

    from servotau.identification.workbench import get_effect, register_effect, unregister_effect

    assert get_effect("thermal_drift").coefficient_range == (-np.inf, 0.0)
    register_effect(replace(get_effect("thermal_drift"), name="thermal_free", coefficient_range=None))
    try:
        d = diagnose(grows, parse_spec("coulomb", grows.signals), effects=["thermal_drift", "thermal_free"])
    finally:
        unregister_effect("thermal_free")
    free = d.candidate("thermal_free")  # measured: 90 %, the simulated +1e-4
    assert free.heldout_gain > 0.5 and free.coefficient > 0 and free.shape["gain"] == 0.0, free
    # the friction form admits no shape (its coefficient would be > 0); the gain form removes nothing held out
    assert d.top.effect == "thermal_free" and d.candidate("thermal_drift").heldout_gain <= 0.0, d.message


def _with_lead_share(share: float):
    """The synthetic log where, above the 90 % quantile of the motor-torque proxy (a shape of the saturation grid),
    the error keeps ``share`` of the command's lead since the onset: ``y = y_base + share (lead(t) - lead(t_on))``
    with ``lead = q_des(t - 1) - q(t)``, computed tick by tick (the term reads the error it adds to), where that
    lead grows in the direction of the torque (at a current limit the servo asks for more than it gets)."""
    from servotau.actuator.effects.saturation import motor_torque_proxy
    from servotau.actuator.signals import hysteresis, run_onsets
    from servotau.identification.workbench import get_effect

    base = synthetic_table(noise=0.0)
    s = load_dataset(base).signals
    grid = get_effect("saturation").grid_for(s)
    beta = sorted({g["beta"] for g in grid})[2]  # 1 x P99|tau| / P99|dq|
    shape = sorted((g for g in grid if g["beta"] == beta), key=lambda g: g["tau_sat"])[2]  # its 90 % quantile
    proxy = motor_torque_proxy(s, shape["beta"])
    flag = hysteresis(np.abs(proxy), shape["tau_sat"], shape["release"] * shape["tau_sat"])
    onset = run_onsets(flag)
    q, y = base["q"], base["q_des"] - base["q"]
    out = y.copy()
    for i in np.flatnonzero(flag):
        j = max(onset[i], 1)
        grown = (q[i - 1] + out[i - 1] - q[i]) - (q[j - 1] + out[j - 1] - q[j])
        out[i] = y[i] + share * grown * (grown * proxy[i] > 0)
    return load_dataset({**base, "q_des": q + out}), flag.mean()


def test_saturation_coefficient_is_between_half_and_one_and_a_half():
    """Past a current limit the error keeps all of the command's lead (coefficient 1): a share in (0.5, 1.5) is
    named; where the servo still closes 80 % of it (share 0.2, the 0.13 fitted on a simulated log without a limit)
    the detector found no limit, and the term is not named although an unconstrained term fits it."""
    from dataclasses import replace

    from servotau.identification.workbench import get_effect, register_effect, unregister_effect

    assert get_effect("saturation").coefficient_range == (0.5, 1.5)
    register_effect(replace(get_effect("saturation"), name="saturation_free", coefficient_range=None))
    try:
        low, share = _with_lead_share(0.2)
        assert 0.05 < share < 0.3
        d = diagnose(low, parse_spec("coulomb", low.signals), effects=["saturation", "saturation_free"])
        free = d.candidate("saturation_free")  # measured: 100 %, coefficient 0.200; in range (0.8): 0.801
        assert free.heldout_gain > 0.5 and abs(free.coefficient - 0.2) < 0.05, (free.heldout_gain, free.coefficient)
        # one shape's fit lands just inside the range (0.51: the term is one-sided, so half the lead fits half of
        # it) and fails its held-out blocks (-162 %): never named
        assert d.candidate("saturation").heldout_gain < 0.0 and d.top.effect != "saturation", d.message
        at, _ = _with_lead_share(0.8)
        d = diagnose(at, parse_spec("coulomb", at.signals), effects=["saturation"])
        assert d.top.effect == "saturation" and d.top.heldout_gain > 0.5, d.message
        assert abs(d.top.coefficient - 0.8) < 0.1, d.top.coefficient
    finally:
        unregister_effect("saturation_free")


def test_runner_up_is_another_effect_when_the_first_ranked_fails_in_too_many_blocks():
    """The named effect is the best consistent one; the runner-up shown is the best other effect, never itself."""
    from dataclasses import replace

    from servotau.identification.workbench import resolve_shapes
    from servotau.identification.workbench.verdict import verdict_of

    ds = load_dataset(synthetic_table(cogging_truth))
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    spec = resolve_shapes(ds.signals, ds.target, parse_spec("coulomb", ds.signals), Loss(), {})  # as diagnose does
    tested = [c for c in d.ranking if c.testable]
    first = replace(tested[1], heldout_gain=0.9, consistent=False)  # better, but fails in too many blocks
    again = verdict_of(ds, spec, d.base, [first, tested[0], *tested[2:]], d.probes, d.excitation, d.min_gain)
    assert again.message.startswith(f"missing effect: {tested[0].effect}"), again.message
    assert f"runner-up {first.effect} (90 %)" in again.message, again.message
    assert again.top is tested[0] and again.runner_up is first  # what the ladder adds is what the message names


def test_the_next_effect_to_add_is_scored_over_the_model_with_the_named_one():
    """Coulomb friction and a position ripple, diagnosed from the paper's model: the ripple is named; Coulomb,
    which removes little over the paper's model (the ripple hides it), removes most of the rest once the ripple
    is in: it is the next to add, with its gain over the model with the ripple."""
    ds = load_dataset(synthetic_table(cogging_truth))
    d = diagnose(ds, parse_spec("paper", ds.signals), effects=["coulomb", "stribeck", "cogging", "delay"])
    assert d.verdict == "missing_effect" and d.top.effect == "cogging", d.message
    assert d.then is not None and d.then.effect == "coulomb", d.message
    assert d.then.heldout_gain > 0.5 > d.candidate("coulomb").heldout_gain, d.message
    assert "coulomb removes a further" in d.message and d.to_dict()["then"]["effect"] == "coulomb"


@pytest.mark.slow  # 8 s (the default suite's budget); the offset's own tests stay in it
def test_a_constant_error_is_not_named_as_a_lag():
    """A driver dead zone under a gravity load that never changes sign (plant 67 of the independent family, held
    out) is a constant error: the paper model, without an offset, biases k_tau, and `delay` fitted the bias (62 %).
    Nothing that loses its gain once an offset is in the model is named; the message says to add the offset, and
    with it nothing is missing."""
    from servotau.experiments import plant_family as pf

    plant = pf.draw_plant(67)
    (true,) = pf.simulate([plant])
    assert plant.hidden == ("deadzone",) and np.all(true["tau"] <= 0)  # the load never changes sign
    ds = load_dataset(dict(pf.measure(plant, true)))
    d = diagnose(ds, parse_spec("paper", ds.signals))
    assert d.verdict != "missing_effect", d.message
    assert "constant error" in d.candidate("delay").reason and any("--offset on" in c for c in d.checks), d.message
    with_offset = diagnose(ds, parse_spec("paper", ds.signals, offset=True))
    assert with_offset.verdict == "no_missing_effect", with_offset.message


@pytest.mark.slow  # 8 s per plant
@pytest.mark.parametrize(("seed", "effect", "form"), [
    (2152, "deadzone", None),  # a driver dead zone whose torque never reverses at rest (coulomb removes 0 %)
    (2168, "motor_lag", {"time_constant": 0.0}),  # a 6.3 ms current loop at 4 ms: the derivative form
    (2091, "saturation", {"beta": 0.0}),  # a current limit reached on 28 % of the samples at 11 ms
    (2364, "cogging", None),  # a ripple swept densely over 60 % of the range, sparsely elsewhere, at 15 ms
])
def test_plants_of_the_development_set_name_their_effect(seed, effect, form):
    """Plants of the independent family's development seeds (2000-2399), on which the look-alike rule, the
    derivative form of motor_lag, saturation's beta = 0 and the dense stretch of cogging were found: the hidden
    effect is named first."""
    from servotau.experiments import plant_family as pf

    plant = pf.draw_plant(seed)
    assert effect in plant.hidden
    (true,) = pf.simulate([plant])
    ds = load_dataset(dict(pf.measure(plant, true)))
    d = diagnose(ds, parse_spec("paper", ds.signals))
    assert d.verdict == "missing_effect" and d.top.effect == effect, d.message
    assert form is None or all(d.top.shape[k] == v for k, v in form.items()), d.top.shape


@pytest.mark.slow  # 8 s
def test_a_clean_plant_whose_torque_was_smoothed_long_is_not_named_a_delay():
    """Development plant 2603 forced clean (6 ms, a noisy torque smoothed over 69 samples): the torque's noise and
    the long order-2 smoothing's error looked like a delay (17 %). The delay removes 65 urad RMS, within the torque's
    noise times k_tau (78 urad RMS); with the torque smoothed by a quartic fit over the same window it removed 3 %.
    It is untestable for a reason about the torque (the noise floor comes first), and nothing is named."""
    from servotau.experiments import plant_family as pf

    plant = pf.draw_plant(2603, hidden=())
    (true,) = pf.simulate([plant])
    ds = load_dataset(dict(pf.measure(plant, true)))
    assert ds.preprocessing["tau"]["window"] == 69
    d = diagnose(ds, parse_spec("paper", ds.signals))
    assert d.verdict != "missing_effect", d.message
    reason = d.candidate("delay").reason
    assert "the torque's noise times k_tau" in reason or "torque smoothing's error" in reason, reason


def test_a_torque_constant_falling_with_heat_is_named_in_the_gain_form():
    """The servo needs more error for the same torque as the winding heats (the torque part scaled by 1 + a h):
    thermal_drift is named in its gain form (-h u_tau), with the coefficient -a."""
    drop = load_dataset(synthetic_table(lambda t, q, dq, tau: 0.05 * _heat(dq, tau) * K_TAU * tau))
    d = diagnose(drop, parse_spec("coulomb", drop.signals), effects=["thermal_drift", "stribeck", "delay"])
    assert d.top.effect == "thermal_drift" and d.top.shape["gain"] == 1.0, d.message
    assert d.top.coefficient == pytest.approx(-0.05, rel=0.3)


def _candidate(effect: str, gain: float):
    from servotau.identification.workbench.verdict import Candidate

    return Candidate(effect, gain, 1.0 - gain, gain, (gain,) * 4, True, {}, 1.0, False, True, None, "x")


def test_the_shortlist_puts_the_next_to_add_second():
    """Greedy forward selection: the first effect, then the best one over the model with it (its look-alikes, which
    rank second over the base model, explain nothing more); without a next to add, the ranking's first two."""
    from servotau.identification.workbench.verdict import Diagnosis

    then = _candidate("cogging", 0.3)
    ranking = (_candidate("coulomb", 0.5), _candidate("direction_gain", 0.45), _candidate("cogging", 0.1))
    d = Diagnosis("missing_effect", None, ranking, {}, None, 0.1, then=then)
    assert [c.effect for c in d.shortlist] == ["coulomb", "cogging"]
    alone = Diagnosis("missing_effect", None, ranking, {}, None, 0.1)
    assert [c.effect for c in alone.shortlist] == ["coulomb", "direction_gain"]


def test_a_tied_rival_is_the_next_effect_within_tie_that_does_not_nest_the_first():
    """A runner-up whose held-out error is within TIE of the first's is as good a first (diagnose then orders the two
    by the error after their next effects); one that nests the first (the Stribeck curve, Coulomb) is no rival."""
    from servotau.identification.workbench.verdict import TIE, tied_rival

    first = _candidate("coulomb", 0.5)
    tie = 1.0 - (1.0 + TIE / 2) * 0.5  # held-out error within TIE of the first's
    assert tied_rival([first, _candidate("direction_gain", tie)], first).effect == "direction_gain"
    assert tied_rival([first, _candidate("direction_gain", 0.45)], first) is None
    assert tied_rival([first, _candidate("stribeck", 0.52), _candidate("cogging", 0.45)], first) is None
    assert tied_rival([first, _candidate("stribeck", 0.52), _candidate("load_friction", tie)], first).effect == (
        "load_friction")


def _excitation(**changes):
    """A log that moved both ways under a torque of one sign, never reversed at rest."""
    from servotau.actuator import Excitation

    fields = dict(duration=20.0, n_samples=10000, velocity_reversals=20, hold_time=4.0, slow_time=8.0, fast_time=4.0,
                  quadrants={}, torque_range=(1.0, 5.0), torque_reversals_at_rest=0, torque_reversals=0,
                  loaded_motion=0.5, velocity_range=(-1.0, 1.0), position_range=(0.0, 1.0), period=2e-3)
    return Excitation(**{**fields, **changes})


def test_a_look_alike_reason_holds_only_where_the_look_alike_removes_a_comparable_error():
    """deadzone needs a torque reversal at rest only to tell it from Coulomb friction: where it would be named first
    and coulomb removes at most LOOKALIKE_SHARE of what it removes, the log tells them apart and deadzone is tested,
    saying why; where coulomb comes close, another effect removes more, or the units are doubted, the reason
    stands."""
    from dataclasses import replace

    from servotau.actuator import get_effect
    from servotau.identification.workbench.verdict import LOOKALIKE_SHARE, lookalikes_apart

    exc = _excitation()
    reason = get_effect("deadzone").needs(exc)
    assert reason is not None and "Coulomb" in reason
    dz = replace(_candidate("deadzone", 0.5), testable=False, reason=reason)
    apart, notes = lookalikes_apart([dz, _candidate("coulomb", 0.05)], exc, 0.1)
    assert apart[0].testable and apart[0].reason is None
    assert len(notes) == 1 and "coulomb 5 %" in notes[0] and "deadzone 50 %" in notes[0]
    close = _candidate("coulomb", 0.5 * LOOKALIKE_SHARE + 0.01)
    assert not lookalikes_apart([dz, close], exc, 0.1)[0][0].testable
    ahead = _candidate("cogging", 0.6)  # a testable effect removes more: deadzone would not be named first
    assert not lookalikes_apart([dz, _candidate("coulomb", 0.05), ahead], exc, 0.1)[0][0].testable
    doubted = _excitation(unit_doubts=("the torque reaches 5000 N m",))
    from servotau.actuator.excitation import units_plausible

    doubted_dz = replace(dz, reason=units_plausible(doubted))  # what diagnose gives: the units' reason comes first
    assert not lookalikes_apart([doubted_dz, _candidate("coulomb", 0.0)], doubted, 0.1)[0][0].testable
    other = replace(dz, reason="needs signal(s) ['tau']: not in the log")
    assert not lookalikes_apart([other, _candidate("coulomb", 0.0)], exc, 0.1)[0][0].testable
    assert not lookalikes_apart([dz], exc, 0.1)[0][0].testable  # coulomb never scored: the reason stands
    in_model, notes = lookalikes_apart([dz], exc, 0.1, ("coulomb",))  # scored over a model with coulomb
    assert in_model[0].testable and "coulomb in the model" in notes[0]
    for weak in (replace(dz, consistent=False), replace(dz, heldout_gain=0.05)):  # not nameable anyway
        assert not lookalikes_apart([weak, _candidate("coulomb", 0.0)], exc, 0.1)[0][0].testable
