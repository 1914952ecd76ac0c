"""Tests of servotau.actuator.effects.dahl: the Dahl friction state, batch and on-line, and its recovery."""

import numpy as np
from support.friction_state import dahl_euler
from support.synthetic import synthetic_table

from servotau.actuator import Signals, get_effect
from servotau.actuator.friction_state import affine_scan, x0_grid
from servotau.actuator.online import OnlineModel
from servotau.identification.workbench import diagnose, load_dataset, parse_spec


def _signals(dq, dt=1e-3):
    n = len(dq)
    return Signals({"t": np.arange(n) * dt, "dq": np.asarray(dq, dtype=float)}, dt, n)


def test_after_a_reversal_the_state_follows_one_minus_two_exp_of_the_travel():
    """Settled at -1 by a long move backwards (40 x0), then moving forwards at a constant speed: z = 1 - 2 exp(-x / x0),
    x the travel since the reversal; at rest z holds."""
    from servotau.actuator.effects.dahl import dahl

    dt, v, x0 = 1e-3, 0.1, 1e-3  # [s], [rad/s], [rad]
    dq = np.concatenate([np.full(400, -v), np.full(100, v), np.zeros(50)])
    z = dahl(_signals(dq, dt), x0=x0)
    assert abs(z[399] + 1.0) < 1e-12
    # the first forward tick travels half a tick's distance (mean velocity 0: the reversal sits mid-tick)
    travel = (np.arange(1, 101) - 1) * v * dt
    np.testing.assert_allclose(z[400:500], 1.0 - 2.0 * np.exp(-travel / x0), rtol=1e-12, atol=1e-12)
    # at rest: held (the first rest tick travels half a tick)
    np.testing.assert_allclose(z[501:], z[500], rtol=0, atol=1e-15)
    assert np.all(np.abs(z) <= 1.0)


def test_the_scan_is_the_recursion():
    """The prefix scan gives z[k] = a[k] z[k-1] + b[k] of a loop, to rounding."""
    rng = np.random.default_rng(3)
    a, b = rng.uniform(0, 1, 5000), rng.normal(size=5000)
    z, out = 0.0, []
    for ak, bk in zip(a, b, strict=True):
        z = ak * z + bk
        out.append(z)
    np.testing.assert_allclose(affine_scan(a, b), out, rtol=1e-10, atol=1e-12)


def test_online_equals_batch_sample_by_sample():
    """The on-line state (value before commit, one commit per tick) gives the batch regressor's numbers."""
    rng = np.random.default_rng(0)
    dt = 2e-3
    dq = np.cumsum(rng.normal(size=600)) * 0.02
    dq[300:340] = 0.0
    e = get_effect("dahl")
    s = _signals(dq, dt)
    for shape in e.grid_for(s)[:3]:
        term = e.online(shape, dt)
        one = []
        for v in dq:
            x = {"dq": float(v)}
            one.append(term.value(x))
            assert term.value(x) == one[-1]  # value does not advance the state
            term.commit(x)
        np.testing.assert_allclose(one, e.evaluate(s, shape), rtol=1e-10, atol=1e-12)


def test_the_grid_spans_one_tick_of_travel_to_half_a_stroke():
    """x0 from the travel of one tick at the median moving speed to half the median stroke between reversals."""
    dt = 1e-3
    t = np.arange(20000) * dt
    dq = 0.5 * np.sin(2 * np.pi * 1.0 * t)  # strokes of 2 * 0.5 / (2 pi) = 0.159 rad
    g = x0_grid(_signals(dq, dt))
    assert 2 <= len(g) <= 6 and list(g) == sorted(g)
    assert 0.2e-3 < g[0] < 0.5e-3  # median |dq| about 0.35 rad/s: 0.35 mrad per tick
    assert 0.02 < g[-1] <= 0.5 * 0.159


def test_hidden_dahl_friction_is_named_first():
    """A Dahl friction (x0 = 3 mrad, integrated by a fine-step Euler of its ODE, not by the regressor) hidden in
    a log: the diagnosis from the Coulomb model names dahl, removing most of the held-out error."""
    base = synthetic_table(seconds=8.0)
    z = dahl_euler(base["dq"], 1e-3, 3e-3)
    ds = load_dataset(synthetic_table(lambda t, q, dq, tau: 3e-4 * z, seconds=8.0))
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert d.verdict == "missing_effect" and d.top.effect == "dahl", d.message
    assert d.top.heldout_gain > 0.5 and 1e-3 < d.top.shape["x0"] < 1e-2, (d.top.heldout_gain, d.top.shape)
    assert abs(d.top.coefficient - 3e-4) < 0.2 * 3e-4, d.top.coefficient


def test_the_online_model_with_a_dahl_term_matches_the_batch_prediction():
    """A motor model with a dahl term, evaluated on-line tick by tick, predicts the batch numbers."""
    from servotau.actuator.model import EffectTerm, MotorModel
    from servotau.actuator.online import predict_batch

    rng = np.random.default_rng(1)
    dt = 1e-3
    dq = np.sin(np.arange(400) * 0.05) * 0.2 + 0.01 * rng.normal(size=400)
    tau = rng.normal(size=400)
    model = MotorModel(k_tau=5e-5, k_v=6e-3, extra={"dahl": EffectTerm(3e-4, {"x0": 2e-3})}, provenance="test")
    batch = predict_batch(model, tau, dq, t=np.arange(400) * dt)
    om = OnlineModel(model, dt)
    online = [om.step(a, v, t=k * dt) for k, (a, v) in enumerate(zip(tau, dq, strict=True))]
    np.testing.assert_allclose(online, batch, rtol=1e-9, atol=1e-15)
