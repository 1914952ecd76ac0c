"""The encoder's resolution read off the log, and no effect named within its rounding error."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from servotau.actuator.excitation import noise_floor
from servotau.identification.workbench import diagnose, load_dataset, parse_spec
from servotau.identification.workbench.resolution import encoder_resolution, quantisation_floor


def test_the_lattice_of_a_quantised_angle_is_its_resolution():
    res = 2 * math.pi / 2**13
    t = np.linspace(0.0, 10.0, 5000)
    q = np.round((0.4 * np.sin(t) + 0.123) / res) * res
    assert math.isclose(encoder_resolution(q), res, rel_tol=1e-9)
    assert math.isclose(quantisation_floor(res), res / math.sqrt(12))


def test_an_unquantised_angle_has_no_resolution():
    t = np.linspace(0.0, 10.0, 5000)
    assert encoder_resolution(0.4 * np.sin(t) + 1e-7 * np.random.default_rng(0).normal(size=t.size)) == 0.0
    assert encoder_resolution(np.zeros(10)) == 0.0


def test_clean_plants_with_a_coarse_encoder_raise_no_alarm():
    """The independent plant family's clean servo, its encoder at 2^13 counts per turn: holds that return to one
    angle share one rounding offset, which holding-versus-moving terms and the probes fit. No effect is named; what
    the probes remove within the rounding error is said."""
    from servotau.experiments import plant_family as pf

    plants = [replace(pf.draw_plant(s, hidden=(), period=1e-3, duration=12.0), res=2 * math.pi / 2**13)
              for s in (1089, 1090)]
    checks = []
    for plant, true in zip(plants, pf.simulate(plants, 12.0), strict=True):
        ds = load_dataset(dict(pf.measure(plant, true)))
        assert math.isclose(ds.preprocessing["q"]["resolution"], plant.res, rel_tol=1e-6)
        assert any(n.startswith("q: quantised to") for n in ds.notes)
        d = diagnose(ds, parse_spec("paper", ds.signals))
        assert d.verdict != "missing_effect"
        checks += d.checks
    assert any("within the log's noise floor" in c and "the encoder's rounding error" in c for c in checks)


def _slow_log(dt=2e-3, duration=8.0, sigma_tau=0.2, res=None, seed=3):
    """A slow servo log: q a sum of two slow sines (optionally quantised to ``res``), the torque 20 q plus white
    noise of ``sigma_tau`` [N m]; returns the columns and the noise-free q, dq and torque."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, dt)
    w1, w2 = 2 * math.pi * 0.3, 2 * math.pi * 0.7
    q = 0.5 * np.sin(w1 * t) + 0.2 * np.sin(w2 * t)
    dq = 0.5 * w1 * np.cos(w1 * t) + 0.2 * w2 * np.cos(w2 * t)
    tau = 20.0 * q
    q_log = q if res is None else np.round(q / res) * res
    cols = {"t": t, "q": q_log, "q_des": q + tau / 1000.0, "tau": tau + rng.normal(0.0, sigma_tau, t.size)}
    return cols, q, dq, tau


def test_the_torque_noise_floor_is_k_tau_times_the_noise_left_after_smoothing():
    """What the smoothed torque still carries of its white noise, measured against the noise-free torque, is what
    the floor says, with and without the workbench's smoothing."""
    from servotau.identification.workbench.resolution import torque_noise_floor

    k_tau = 1e-3
    for smooth in (None, 0.0, 0.05):
        cols, _, _, tau = _slow_log()
        ds = load_dataset(cols, smooth_torque_s=smooth)
        left = float(np.std(ds.signals["tau"] - tau))  # the slow torque passes the smoothing unchanged
        assert math.isclose(torque_noise_floor(ds, k_tau), k_tau * left, rel_tol=0.1), smooth
    assert torque_noise_floor(ds, 0.0) == 0.0  # no torque regressor, no floor


def test_the_velocity_noise_floor_is_k_v_times_the_rounding_through_the_derivative():
    """The derivative of a quantised angle carries the rounding error through the filter: the floor matches what
    the rounding adds to the velocity (the same filter on the unrounded angle as reference: the filter is linear)."""
    from servotau.identification.workbench.resolution import velocity_noise_floor

    for res in (2 * math.pi / 2**14, 2 * math.pi / 2**17):
        cols, q, _, _ = _slow_log(res=res)
        ds = load_dataset(cols)
        assert math.isclose(ds.preprocessing["q"]["resolution"], res, rel_tol=1e-6)
        exact = load_dataset({**cols, "q": q}, dq_window=ds.preprocessing["dq"]["window"],
                             dq_order=ds.preprocessing["dq"]["order"])
        added = float(np.std(ds.signals["dq"] - exact.signals["dq"]))
        assert 0.7 < velocity_noise_floor(ds, 1.0) / added < 1.3, res
    assert velocity_noise_floor(ds, 0.0) == 0.0


def test_a_clean_stiff_plant_with_a_noisy_torque_raises_no_alarm():
    """Plant family seed 2401, no hidden effect: a stiff servo (3695 N m/rad) at 3 ms whose torque noise accounts
    for 8.7 of its 31 urad RMS held-out error. A delay of the command stands in for the noisy torque and the
    velocity's error (it removed 45 % held out); it removes no more than the noise floor once the velocity is less
    biased, and is not named; the reason says so."""
    from servotau.experiments import plant_family as pf

    plant = pf.draw_plant(2401, hidden=())
    ds = load_dataset(dict(pf.measure(plant, pf.simulate([plant])[0])))
    d = diagnose(ds, parse_spec("paper", ds.signals))
    assert d.verdict == "no_missing_effect", d.message
    delay = next(c for c in d.ranking if c.effect == "delay")
    assert not delay.testable and "noise floor" in delay.reason, delay.reason


def test_white_encoder_noise_is_a_floor_too():
    """A clean servo (the paper's two terms exact) whose encoder is not quantised but noisy (1 mrad white): the
    servo error holds that noise sample by sample, and an acceleration term that reads the angles around the sample
    fitted 14 % of it held out. It removes no more than the encoder's noise, and is not named."""
    rng = np.random.default_rng(4)
    t = np.arange(20000) * 1e-3
    q = 0.5 * np.sin(2 * np.pi * 0.3 * t) + 0.2 * np.sin(2 * np.pi * 1.1 * t + 0.3)
    dq = np.gradient(q, t)
    tau = 20 * np.sin(q + 0.4) + 3 * np.sin(2 * np.pi * 0.7 * t)
    cols = {"t": t, "q": q + rng.normal(0, 1e-3, t.size), "q_des": q + 2e-3 * tau + 5e-3 * dq,
            "tau": tau + rng.normal(0, 0.05, t.size)}
    ds = load_dataset(cols)
    assert ds.preprocessing.get("q", {}).get("resolution", 0.0) == 0.0
    d = diagnose(ds, parse_spec("paper", ds.signals), effects=["elastic", "backlash", "delay", "motor_lag"])
    assert d.verdict == "no_missing_effect", d.message
    elastic = d.candidate("elastic")
    assert not elastic.testable and "the encoder's noise" in elastic.reason, elastic.reason


def test_the_white_noise_level_leaves_out_a_smooth_motion_at_coarse_periods():
    """The encoder's white-noise floor of an unquantised angle reads its noise, not the motion's curvature: a 2 Hz,
    0.5 rad sine sampled every 20 ms gives 0.2 mrad without noise, and its 1 mrad of noise with it."""
    t = np.arange(2000) * 0.02
    q = 0.5 * np.sin(2 * np.pi * 2.0 * t)
    assert noise_floor(q, difference=4) < 3e-4
    noisy = q + np.random.default_rng(5).normal(0, 1e-3, t.size)
    assert noise_floor(noisy, difference=4) == pytest.approx(1e-3, rel=0.35)
