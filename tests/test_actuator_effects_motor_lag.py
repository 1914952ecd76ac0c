"""``motor_lag``: the motor torque lags the servo's command (a first-order current loop)."""

from __future__ import annotations

import numpy as np

from servotau.actuator import Signals, get_effect
from servotau.actuator.signals import lowpass
from servotau.identification.workbench import diagnose, load_dataset, parse_spec


def test_only_the_torque_part_lags():
    t = np.arange(0.0, 2.0, 1e-3)
    u_tau, u_v = np.sin(2 * np.pi * t), 0.5 * np.cos(7 * t)
    s = Signals({"t": t, "tau": u_tau / 1e-3, "u_tau": u_tau, "u_v": u_v, "u": u_tau + u_v}, 1e-3, t.size)
    col = get_effect("motor_lag").evaluate(s, {"time_constant": 0.01})
    np.testing.assert_allclose(col, lowpass(u_tau, 0.01, 1e-3) - u_tau)


def test_the_derivative_form_is_the_torques_rate_at_any_sample_period():
    """The derivative form is minus the rate of u_tau (its coefficient is -T [s]): sampled every 4 ms or every 1 ms,
    a smooth u_tau gives the same column (the backward difference's rate at mid-step), so a motor file fitted on a
    log at one rate runs as fitted in a controller at another."""
    for dt in (4e-3, 1e-3):
        t = np.arange(0.0, 2.0, dt)
        u_tau = np.sin(2 * np.pi * t)
        s = Signals({"t": t, "tau": u_tau / 1e-3, "u_tau": u_tau, "u_v": 0 * t, "u": u_tau}, dt, t.size)
        col = get_effect("motor_lag").evaluate(s, {"time_constant": 0.0})
        rate = 2 * np.pi * np.cos(2 * np.pi * (t - dt / 2))
        np.testing.assert_allclose(col[1:], -rate[1:], atol=1e-3 * 2 * np.pi)


def test_a_lead_is_not_a_motor_lag():
    eff = get_effect("motor_lag")
    assert eff.admits(-2.0) and not eff.admits(0.5)


def test_a_current_loop_lag_of_an_independent_plant_is_named_with_its_time_constant():
    """servotau/experiments/plant_family.py (written without the workbench) with a 20 ms current loop: the
    workbench names motor_lag, and its coefficient gives the time constant (-coefficient x the shape's, or
    -coefficient itself in the derivative form), which the verdict prints."""
    from servotau.actuator.effects.motor_lag import time_constant_of
    from servotau.experiments import plant_family as pf

    plant = pf.draw_plant(1004, hidden=("motor_lag",), period=2e-3, duration=12.0)
    (true,) = pf.simulate([plant], 12.0)
    ds = load_dataset(dict(pf.measure(plant, true)))
    d = diagnose(ds, parse_spec("paper", ds.signals))
    assert d.verdict == "missing_effect" and d.top.effect == "motor_lag"
    t_fit = time_constant_of(d.top.coefficient, d.top.shape)
    assert abs(t_fit / plant.effect["motor_lag"]["T"] - 1) < 0.25
    form = "derivative form" if d.top.shape["time_constant"] == 0.0 else "lag form"
    assert f"motor_lag ({form}" in d.message and f"time constant {1e3 * t_fit:.3g} ms)" in d.message, d.message


def test_a_model_without_k_tau_cannot_test_a_torque_lag():
    """A model of the servo error without k_tau (a torque column the user left out) gives motor_lag a zero column:
    it is untestable, saying it needs k_tau."""
    from support.synthetic import synthetic_table

    from servotau.identification.workbench.model import ModelSpec

    ds = load_dataset(synthetic_table())
    d = diagnose(ds, ModelSpec(("k_v",), ()), effects=["motor_lag", "coulomb"])
    assert "needs k_tau" in d.candidate("motor_lag").reason
