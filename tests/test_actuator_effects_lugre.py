"""Tests of servotau.actuator.effects.lugre: the LuGre bristle state, batch and on-line, and its recovery."""

import numpy as np
from support.friction_state import lugre_euler
from support.synthetic import synthetic_table

from servotau.actuator import Signals, get_effect
from servotau.identification.workbench import diagnose, load_dataset, parse_spec


def _signals(dq, dt=1e-3):
    n = len(dq)
    return Signals({"t": np.arange(n) * dt, "dq": np.asarray(dq, dtype=float)}, dt, n)


def test_the_steady_state_is_the_stribeck_curve_and_the_transient_dahls():
    """At constant speed the state settles at G(v) = 1 + (Fs/Fc - 1) exp(-(v/v_s)^2) (Fs/Fc at creep, 1 fast);
    after a reversal from -G it follows G - 2 G exp(-x / (x0 G)); with Fs/Fc = 1 it is dahl's state."""
    from servotau.actuator.effects.dahl import dahl
    from servotau.actuator.effects.lugre import lugre

    dt, x0, r, v_s = 1e-3, 1e-3, 2.0, 0.05
    for v in (0.005, 0.05, 0.5):  # [rad/s]
        g = 1.0 + (r - 1.0) * np.exp(-((v / v_s) ** 2))
        travel_back = 60 * x0 * g
        n_back = int(np.ceil(travel_back / (v * dt)))
        dq = np.concatenate([np.full(n_back, -v), np.full(200, v)])
        w = lugre(_signals(dq, dt), x0=x0, fs_ratio=r, v_s=v_s)
        assert abs(w[n_back - 1] + g) < 1e-12 * g
        travel = np.arange(200) * v * dt  # the reversal sits mid-tick: the first forward tick travels nothing
        np.testing.assert_allclose(w[n_back:], g - 2 * g * np.exp(-travel / (x0 * g)), rtol=1e-9, atol=1e-12)
    rng = np.random.default_rng(2)
    dq = np.cumsum(rng.normal(size=500)) * 0.01
    s = _signals(dq)
    np.testing.assert_allclose(lugre(s, x0=2e-3, fs_ratio=1.0, v_s=0.1), dahl(s, x0=2e-3), rtol=0, atol=1e-15)


def test_online_equals_batch_sample_by_sample():
    """The on-line bristle state gives the batch regressor's numbers, tick by tick."""
    rng = np.random.default_rng(0)
    dt = 4e-3
    dq = np.cumsum(rng.normal(size=500)) * 0.01
    dq[200:260] = 0.0
    e = get_effect("lugre")
    s = _signals(dq, dt)
    for shape in e.grid_for(s)[::7]:
        term = e.online(shape, dt)
        one = []
        for v in dq:
            one.append(term.value({"dq": float(v)}))
            term.commit({"dq": float(v)})
        np.testing.assert_allclose(one, e.evaluate(s, shape), rtol=1e-10, atol=1e-12)


def test_the_regressor_follows_a_fine_step_integration_of_the_ode():
    """On a smooth motion the per-tick exact steps agree with a fine-step Euler of the LuGre ODE (20 steps per
    tick) within 2 % of Fs/Fc: the discretisation is not what a diagnosis would see."""
    from servotau.actuator.effects.lugre import lugre

    base = synthetic_table(seconds=4.0)
    dq = base["dq"]
    w = lugre(_signals(dq), x0=3e-3, fs_ratio=2.0, v_s=0.05)
    ref = lugre_euler(dq, 1e-3, 3e-3, 2.0, 0.05)
    assert np.max(np.abs(w - ref)) < 0.02 * 2.0, np.max(np.abs(w - ref))


def test_hidden_lugre_friction_is_named_first():
    """A LuGre friction (x0 = 3 mrad, Fs/Fc = 2.5, v_s = 0.06 rad/s; a fine-step Euler of its ODE) hidden in a log:
    the diagnosis from the Coulomb model names lugre, removing most of the held-out error."""
    base = synthetic_table(seconds=8.0)
    w = lugre_euler(base["dq"], 1e-3, 3e-3, 2.5, 0.06)
    ds = load_dataset(synthetic_table(lambda t, q, dq, tau: 2e-4 * w, seconds=8.0))
    d = diagnose(ds, parse_spec("coulomb", ds.signals))
    assert d.verdict == "missing_effect" and d.top.effect == "lugre", d.message
    assert d.top.heldout_gain > 0.5, d.top.heldout_gain
