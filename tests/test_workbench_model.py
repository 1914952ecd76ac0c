"""Tests of the workbench model, the motor-parameter file with extra terms and the on-line evaluation
(identification/workbench/model.py; actuator/online.py, registry.py; MotorModel.predict/online)."""

from dataclasses import replace

import numpy as np
import pytest
from support.synthetic import synthetic_table

from servotau.actuator import ONLINE_SIGNALS, OnlineModel
from servotau.errors import IdentificationError
from servotau.identification import EffectTerm, MotorModel, MotorParameters
from servotau.identification.workbench import (
    Effect,
    FittedModel,
    ModelSpec,
    Term,
    effect_names,
    fit_spec,
    get_effect,
    load_dataset,
    register_effect,
)
from servotau.identification.workbench.ladder import add_effects, save_model

LIBRARY = ("coulomb", "coulomb_asym", "stribeck", "stiction", "deadzone", "direction_gain", "backlash",
           "load_friction", "cogging", "thermal_drift", "saturation", "elastic", "motor_lag", "delay")

SHAPES = {
    "coulomb": {"v_eps": 0.01}, "coulomb_asym": {"v_eps": 0.02}, "stribeck": {"v_s": 0.08, "v_eps": 0.01},
    "stiction": {"v_th": 0.01}, "deadzone": {"band": 3e-4, "damping_share": 0.67, "v_th": 0.02},
    "direction_gain": {"v_eps": 0.02}, "backlash": {"window": 0.011, "tau_band": 5.0, "gain": 1.0, "lag": 0.005},
    "load_friction": {"v_eps": 0.02}, "cogging": {"period": 0.08, "phase": 0.3}, "thermal_drift": {"tau_th": 30.0},
    "saturation": {"tau_sat": 30.0, "beta": 5.0, "release": 0.8}, "elastic": {"window": 0.011, "lag": 0.002},
    "motor_lag": {"time_constant": 0.01}, "delay": {"delay": 0.005},
}


def model_with(*effects) -> MotorModel:
    coefs = {"coulomb": 1e-4, "stribeck": 2e-4, "cogging": 1e-4, "deadzone": 1e-4, "direction_gain": -0.05,
             "delay": 0.5, "motor_lag": 0.3, "thermal_drift": 1e-4, "stiction": 5e-5, "elastic": 3e-5,
             "backlash": 3e-5, "load_friction": 2e-6, "coulomb_asym": 5e-5, "saturation": 1.0}
    extra = {e: EffectTerm(coefs[e], SHAPES[e]) for e in effects}
    return MotorModel(k_tau=5e-5, k_v=6e-3, k_c=None if "coulomb" in effects else 1e-4, extra=extra,
                      provenance="test")


def signals(seconds=2.0):
    c = synthetic_table(seconds=seconds)
    ddq = np.gradient(c["dq"], 1e-3)
    return c, ddq


def test_library_has_every_effect_of_the_issue_with_docs():
    """All fourteen effects are registered, each with a signature, a family and its on-line signals."""
    assert set(LIBRARY) <= set(effect_names())
    for name in LIBRARY:
        e = get_effect(name)
        assert e.signature and e.description and name in ONLINE_SIGNALS


def test_motor_model_predict_evaluates_extra_terms_through_the_registry():
    """MotorModel.predict with extra terms equals the workbench model; a missing signal is named."""
    c, ddq = signals()
    m = model_with(*SHAPES)
    pred = m.predict(c["tau"], c["dq"], q=c["q"], q_des=c["q_des"], t=c["t"], ddq=ddq)
    assert pred.shape == c["tau"].shape and np.all(np.isfinite(pred))
    with pytest.raises(IdentificationError, match=r"extra term 'cogging' needs signal\(s\) \['q'\]"):
        model_with("cogging").predict(c["tau"], c["dq"])
    plain = MotorModel(k_tau=5e-5, k_v=6e-3, k_c=1e-4, provenance="test")
    expected = 5e-5 * c["tau"] + 6e-3 * c["dq"] + 1e-4 * np.sign(c["dq"])
    np.testing.assert_allclose(plain.predict(c["tau"], c["dq"]), expected)


@pytest.mark.parametrize("effect", LIBRARY)
def test_online_evaluation_matches_the_batch_one(effect):
    """Tick by tick (effects with memory keep their state), the on-line model equals MotorModel.predict."""
    c, ddq = signals(1.0)
    _assert_online_equals_batch(model_with(effect), c, ddq)


def _assert_online_equals_batch(m: MotorModel, c, ddq) -> np.ndarray:
    """``m`` on the log ``c`` tick by tick (effects with memory keep their state) equals ``m.predict``; that
    prediction."""
    batch = m.predict(c["tau"], c["dq"], q=c["q"], q_des=c["q_des"], t=c["t"], ddq=ddq, period=1e-3)
    online = m.online(1e-3)
    ticks = [online.step(c["tau"][k], c["dq"][k], q=c["q"][k], q_des=c["q_des"][k], t=c["t"][k], ddq=ddq[k])
             for k in range(len(c["t"]))]
    np.testing.assert_allclose(ticks, batch, rtol=1e-9, atol=1e-15)
    return batch


@pytest.mark.parametrize("effect", ["motor_lag", "saturation", "delay"])
def test_online_matches_the_batch_one_in_the_other_forms(effect):
    """motor_lag's derivative form (time_constant 0: the last tick of u_tau), saturation with beta 0 (the logged
    torque is the motor's; the term grows only in the torque's direction) and delay's velocity form (delay 0: the
    command's last step over the period) are evaluated on-line as in batch, and the term is not zero on the log."""
    c, ddq = signals(1.0)
    shape = {"motor_lag": {"time_constant": 0.0}, "delay": {"delay": 0.0}}.get(effect) or {
        "tau_sat": float(np.quantile(np.abs(c["tau"]), 0.8)), "beta": 0.0, "release": 0.8}
    m = replace(model_with(), extra={effect: EffectTerm(model_with(effect).extra[effect].coefficient, shape)})
    batch = _assert_online_equals_batch(m, c, ddq)
    assert np.ptp(batch - model_with().predict(c["tau"], c["dq"])) > 0


def test_online_command_solves_for_the_delayed_command():
    """With a delay term the model is affine in q_des: command() returns q_des with q_des - q = model."""
    m = model_with("delay")
    on, check = m.online(1e-3), m.online(1e-3)
    q_des = []
    for k in range(50):
        q, tau, dq = 0.1 + 0.001 * k, 10.0, 0.5
        qd = on.command(q, tau, dq, t=k * 1e-3)
        q_des.append(qd)
        assert qd - q == pytest.approx(check.step(tau, dq, q=q, q_des=qd, t=k * 1e-3), abs=1e-12)
    with pytest.raises(IdentificationError, match="missing signal"):
        OnlineModel(m, 1e-3).step(1.0, 0.1)


def test_online_saturation_term_does_not_read_this_ticks_command():
    """Past the limit the command does not set the torque: the on-line term reads the previous commands
    only, so command() solves for q_des without dividing by a slope near zero."""
    m = model_with("saturation")
    on = m.online(1e-3)
    for k in range(20):
        q = 1e-4 * k
        on.step(40.0, 0.0, q=q, q_des=q + 3e-3 + 1e-3 * k, t=1e-3 * k)  # held at the limit, the command running ahead
    a = on.predict(40.0, 0.0, q=0.002, q_des=0.0, t=0.02)
    b = on.predict(40.0, 0.0, q=0.002, q_des=1.0, t=0.02)
    assert a == b and a != 5e-5 * 40.0


CROSSING = {"band": 3e-4, "damping_share": 0.0, "crossing": 1.0, "width": 2e-3}


def test_deadzone_crossing_form_reads_the_command_online_and_offline():
    """Only the crossing form needs q and q_des (named when missing); on-line it equals the batch evaluation
    and does not read this tick's command, so command() needs no division."""
    from servotau.actuator import required_signals

    c, _ = signals(1.0)
    legacy, crossing = model_with("deadzone"), MotorModel(k_tau=5e-5, k_v=6e-3, k_c=1e-4, provenance="test",
                                                          extra={"deadzone": EffectTerm(2e-3, CROSSING)})
    assert required_signals(legacy) == [] and required_signals(crossing) == ["q", "q_des"]
    with pytest.raises(IdentificationError, match=r"'deadzone' needs signal\(s\) \['q', 'q_des'\]"):
        crossing.predict(c["tau"], c["dq"])
    batch = crossing.predict(c["tau"], c["dq"], q=c["q"], q_des=c["q_des"])
    u = 5e-5 * c["tau"] + 6e-3 * c["dq"] + 1e-4 * np.sign(c["dq"])
    assert 0.05 < np.mean(np.abs(u) <= CROSSING["band"]) < 0.95  # the log enters and leaves the band
    on = crossing.online(1e-3)
    ticks = [on.step(c["tau"][k], c["dq"][k], q=c["q"][k], q_des=c["q_des"][k]) for k in range(len(c["t"]))]
    np.testing.assert_allclose(ticks, batch, rtol=1e-9, atol=1e-15)
    a = on.predict(1.0, 0.0, q=0.0, q_des=0.0)
    assert a == on.predict(1.0, 0.0, q=0.0, q_des=1.0)
    assert on.command(0.0, 1.0, 0.0) == pytest.approx(a)


def test_fitted_model_round_trips_through_the_motor_parameter_file(tmp_path):
    """add -> save: the TOML file keeps every term and shape; the loaded model predicts the same."""
    ds = load_dataset(synthetic_table(lambda t, q, dq, tau: 2e-4 * np.sin(2 * np.pi * q / 0.08), seconds=6.0))
    lad = add_effects(ds, ModelSpec(("k_tau", "k_v"), (Term("coulomb", {"v_eps": 0.0}),)), effects=["cogging"],
                      diagnose_final=False)
    path = save_model(lad, tmp_path / "motors.toml", "RLEG_JOINT3", provenance="test")
    m = MotorParameters.load_toml(path)["RLEG_JOINT3"]
    assert m.k_c == pytest.approx(lad.final.coefficients["coulomb"]) and set(m.extra) == {"cogging"}
    assert set(m.extra["cogging"].shape) == {"period", "phase"} and m.metrics.n_samples == ds.n
    s = ds.signals
    np.testing.assert_allclose(m.predict(s["tau"], s["dq"], q=s["q"]), lad.final.predict(s), rtol=1e-9, atol=1e-12)
    path.write_text("# identified on robot 7, 2026-11-02\n#   indented: kept as written\n" + path.read_text())
    save_model(lad, path, "RLEG_JOINT2", provenance="test")  # other joints of the file are kept, and its comments
    assert set(MotorParameters.load_toml(path)) == {"RLEG_JOINT3", "RLEG_JOINT2"}
    lines = path.read_text().splitlines()
    assert lines[:2] == ["# identified on robot 7, 2026-11-02", "#   indented: kept as written"]
    assert lines[2] == "# RLEG_JOINT2: replaced by a model fitted on test (what the notes above say of RLEG_JOINT2 " \
                       "predates it)"
    assert sum(line.startswith("# Units:") for line in lines) == 1


def test_fixed_point_model_reproduces_itself():
    """A model with terms reading u (dead zone, direction gain) predicts from its own coefficients."""
    ds = load_dataset(synthetic_table(seconds=4.0))
    spec = ModelSpec(("k_tau", "k_v"), (Term("coulomb", {"v_eps": 0.005}), Term("deadzone", SHAPES["deadzone"]),
                                        Term("direction_gain", SHAPES["direction_gain"])))
    m = fit_spec(ds.signals, ds.target, spec, __import__("servotau.identification", fromlist=["Loss"]).Loss())
    again = FittedModel.from_motor_model(m.to_motor_model("test"))
    np.testing.assert_allclose(again.predict(ds.signals), m.predict(ds.signals), rtol=1e-12, atol=1e-15)


def test_registering_bad_effects_is_refused():
    """Names are identifiers, not reserved; grids are numbers; the registry names unknown effects."""
    with pytest.raises(IdentificationError, match="expected an identifier"):
        register_effect("bad name", lambda s: s["tau"])
    with pytest.raises(IdentificationError, match="other than"):
        register_effect("k_tau", lambda s: s["tau"])
    with pytest.raises(IdentificationError, match="grid entry"):
        Effect("g", lambda s, a: s["tau"], grid=[{"a": "x"}])
    with pytest.raises(IdentificationError, match="unknown effect 'nope': expected one of"):
        get_effect("nope")


def test_greedy_step_that_raises_the_held_out_error_is_rejected_and_stops(monkeypatch):
    """A diagnosis that names an effect the data lacks (motor_lag on 6 s of the linear model with 1 mrad of
    noise): its refit raises the held-out error, so the ladder keeps the rung it started from, lists the
    step as rejected, and stops."""
    from types import SimpleNamespace

    from servotau.identification.workbench import ladder as ladder_module

    ds = load_dataset(synthetic_table(noise=1e-3, seconds=6.0))
    calls = []

    def claims_motor_lag(*_args, **_kwargs):
        calls.append(1)
        return SimpleNamespace(verdict="missing_effect", top=SimpleNamespace(effect="motor_lag", heldout_gain=0.5))

    monkeypatch.setattr(ladder_module, "diagnose", claims_motor_lag)
    lad = add_effects(ds, ModelSpec(("k_tau", "k_v"), (Term("coulomb", {"v_eps": 0.0}),)), max_steps=3)
    assert len(calls) == 1  # stopped after the rejected step
    assert [r.added for r in lad.rungs] == [None] and [r.added for r in lad.rejected] == ["motor_lag"]
    assert lad.rejected[0].comparison.heldout.error > lad.rungs[0].comparison.heldout.error
    assert lad.final is lad.rungs[0].comparison.model and lad.to_dict()["rejected"][0]["added"] == "motor_lag"


@pytest.mark.parametrize("effects", [("thermal_drift", "deadzone"), ("motor_lag", "cogging", "direction_gain")])
def test_online_equals_batch_with_an_offset_and_without_k_tau(effects):
    """A model with a constant offset and no k_tau: tick by tick equals MotorModel.predict (the offset enters
    u, which the terms reading u see, on-line as in the batch), and tau is not needed unless a term reads it."""
    c, ddq = signals(1.0)
    m = MotorModel(k_tau=None, k_v=6e-3, k_c=1e-4, offset=3e-4,
                   extra={e: EffectTerm(model_with(e).extra[e].coefficient, SHAPES[e]) for e in effects},
                   provenance="test")
    batch = m.predict(c["tau"], c["dq"], q=c["q"], q_des=c["q_des"], t=c["t"], ddq=ddq, period=1e-3)
    with_k_tau = MotorModel(**{**m.__dict__, "k_tau": 5e-5})
    shifted = with_k_tau.predict(c["tau"], c["dq"], q=c["q"], q_des=c["q_des"], t=c["t"], ddq=ddq, period=1e-3)
    assert np.max(np.abs(shifted - batch)) > 1e-4  # the torque term is really absent, not hidden
    online = m.online(1e-3)
    ticks = [online.step(c["tau"][k], c["dq"][k], q=c["q"][k], q_des=c["q_des"][k], t=c["t"][k], ddq=ddq[k])
             for k in range(len(c["t"]))]
    np.testing.assert_allclose(ticks, batch, rtol=1e-9, atol=1e-15)
    plain = MotorModel(k_tau=None, k_v=6e-3, offset=3e-4, provenance="test")
    np.testing.assert_allclose(plain.predict(None, c["dq"]), 6e-3 * c["dq"] + 3e-4)
    on = plain.online(1e-3)
    assert [on.step(None, v) for v in c["dq"][:5]] == pytest.approx(list(6e-3 * c["dq"][:5] + 3e-4), abs=1e-18)
    with pytest.raises(IdentificationError, match="tau = None"):
        MotorModel(k_tau=5e-5, k_v=6e-3, provenance="test").online(1e-3).step(None, 0.1)


def _friction_dataset(seed=0, seconds=6.0):
    """A friction table: torque [N m] = 0.2 + 1.5 sign + 3 v + noise (no torque column: no k_tau)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 0.004)
    v = 0.4 * np.sin(2 * np.pi * (0.2 + 0.05 * seed) * t) + 0.2 * np.sin(2 * np.pi * 0.9 * t + seed)
    f = 0.2 + 1.5 * np.tanh(v / 0.01) + 3.0 * v + 0.02 * rng.standard_normal(t.size)
    return load_dataset({"t": t, "v": v, "friction": f}, roles={"time": "t", "velocity": "v", "target": "friction"})


def test_a_friction_model_without_k_tau_with_an_offset_round_trips_through_the_file(tmp_path):
    """k_v + offset + coulomb (smoothed) fitted on a friction torque: saved with its target, unit and offset and without
    k_tau; reloaded, it predicts the same, batch and on-line; the controller's check refuses it."""
    from servotau.errors import ConfigError

    ds = _friction_dataset()
    spec = ModelSpec(("k_v", "offset"), (Term("coulomb", {"v_eps": 0.01}),))
    lad = add_effects(ds, spec, diagnose_final=False, effects=[])
    path = save_model(lad, tmp_path / "f.toml", "J1", provenance="test", target="torque", unit="N m")
    text = path.read_text()
    assert "k_tau" not in text.split("version")[1] and 'target = "torque"' in text and 'unit = "N m"' in text
    m = MotorParameters.load_toml(path)["J1"]
    assert (m.k_tau, m.target, m.unit) == (None, "torque", "N m")
    assert m.offset == pytest.approx(0.2, abs=0.01) and m.k_c is None  # a smoothed sign: an extra term
    assert m.extra["coulomb"].coefficient == pytest.approx(1.5, abs=0.05) and m.k_v == pytest.approx(3.0, abs=0.05)
    s = ds.signals
    batch = m.predict(None, s["dq"])
    np.testing.assert_allclose(batch, lad.final.predict(s), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(FittedModel.from_motor_model(m).predict(s), batch, rtol=1e-12, atol=1e-12)
    on = m.online(ds.dt)
    np.testing.assert_allclose([on.step(None, v) for v in s["dq"]], batch, rtol=1e-12, atol=1e-12)
    with pytest.raises(ConfigError, match=r"f\.toml: field 'joints\.J1\.target' = 'torque' \[N m\]: expected"):
        MotorParameters.load_toml(path).servo_model("J1")


def test_two_recordings_are_each_held_out_from_the_other():
    """Two recordings: two folds, each recording predicted by a model fitted on the other (not halves of the
    joined samples); any number of recordings likewise."""
    from servotau.identification.data.folds import folds_of
    from servotau.identification.workbench.recordings import combine

    parts = [_friction_dataset(i, seconds=s) for i, s in enumerate((6.0, 3.0, 4.0))]
    for k in (2, 3):
        ds = combine(parts[:k])
        folds = folds_of(ds, k)
        assert [f.label for f in folds] == [f"segment {i}" for i in range(k)]
        starts = np.cumsum([0] + [p.n for p in parts[:k]])
        for i, f in enumerate(folds):
            np.testing.assert_array_equal(f.test, np.arange(starts[i], starts[i + 1]))
            assert not f.train[f.test].any() and f.train[np.setdiff1d(np.arange(ds.n), f.test)].sum() > 0.8 * (
                ds.n - f.test.size)
