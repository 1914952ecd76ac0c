"""Testability scaled to the log (issue 18, item 5): the excitation's thresholds come from the log's own velocity
and torque (peak, noise floor) and its sample period, and an untestable effect says the value measured and the
one needed. Generated logs, no diagnosis (fast)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from servotau.actuator import Signals, excitation_report, get_effect
from servotau.actuator.excitation import (
    MAX_ERROR,
    MAX_PERIOD,
    MAX_SPEED,
    MAX_TORQUE,
    TURNS,
    ResolvedGrid,
    noise_floor,
    position_coverage,
    position_noise_fault,
    unit_doubts,
)


def _friction_log(peak=0.005, reverse=True, dt=1e-3, seconds=20.0, seed=0):
    """A friction-like table: a slow velocity (peak ``peak`` rad/s) and its friction torque with noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, dt)
    v = peak * (np.sin(2 * np.pi * 0.2 * t) if reverse else 0.6 + 0.4 * np.sin(2 * np.pi * 0.2 * t))
    v = v + 2e-5 * rng.standard_normal(len(t))
    tau = 0.3 * np.tanh(v / 5e-4) + 0.02 * rng.standard_normal(len(t))
    return Signals({"t": t, "dq": v, "tau": tau}, dt, len(t))


def test_slow_reversing_log_still_tests_friction():
    e = excitation_report(_friction_log())
    assert e.v_peak < 0.006 and e.velocity_reversals >= 2
    for name in ("coulomb", "stribeck", "coulomb_asym"):
        assert get_effect(name).needs(e) is None, name


def test_slow_log_without_reversal_says_so_with_the_values():
    e = excitation_report(_friction_log(reverse=False))
    reason = get_effect("coulomb").needs(e)
    assert reason is not None and "never crosses zero" in reason and "0 velocity reversals" in reason
    assert "expected motion in both directions (>= 2)" in reason


def test_thresholds_scale_with_the_log():
    slow, fast = excitation_report(_friction_log(0.005)), excitation_report(_friction_log(5.0))
    assert 500 < fast.v_fast / slow.v_fast < 2000  # the same motion a thousand times faster
    assert slow.velocity_noise == noise_floor(_friction_log(0.005)["dq"]) and slow.velocity_noise > 0
    assert slow.tau_threshold >= 3 * slow.torque_noise  # sign changes beyond the torque's noise


def test_noise_floor_reads_white_noise_not_motion():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 10.0, 1e-3)
    x = np.sin(2 * np.pi * 0.5 * t) + 0.01 * rng.standard_normal(len(t))
    assert abs(noise_floor(x) - 0.01) < 0.001


def test_fast_motion_reason_names_measured_and_needed():
    e = excitation_report(_friction_log(seconds=0.08))  # 80 samples: too few above half the peak
    reason = get_effect("motor_lag").needs(e)
    assert reason is not None and "fast motion" in reason and "expected >=" in reason and "50 samples" in reason


def test_slow_and_fast_spans_are_samples_of_the_log_for_every_friction_effect():
    """stribeck, lugre and viscous_power need MIN_SPAN samples of slow (and fast) motion: 0.3 s of slow motion
    is too little at 16 ms (19 samples) and enough at 1 ms (300); the reason names the measured and needed spans."""
    from dataclasses import replace

    from servotau.actuator.excitation import MIN_SPAN

    e = excitation_report(_friction_log())
    for period, ok in ((1e-3, True), (16e-3, False)):
        short = replace(e, period=period, slow_time=0.3, fast_time=0.3)
        assert short.min_span == MIN_SPAN * period
        for name in ("stribeck", "lugre", "viscous_power"):
            reason = get_effect(name).needs(short)
            assert (reason is None) == ok, (name, period, reason)
            if not ok:
                assert "slow motion 0.3 s" in reason and "expected >= 0.8 s (50 samples)" in reason, name


def test_lag_shapes_need_the_sample_period_to_resolve_them():
    for name in ("delay", "motor_lag", "elastic", "backlash"):
        grid = get_effect(name).grid
        assert isinstance(grid, ResolvedGrid)
        s1 = _servo_log(1e-3)
        zero = [g for g in grid.shapes if not any(g.get(k, 0.0) for k in grid.keys)] if grid.zero_alone else []
        assert len(get_effect(name).grid_for(s1)) == len(grid.shapes) - len(zero)  # 1 kHz resolves every shape
        if name == "delay":
            assert zero == [{"delay": 0.0}]  # the velocity form only where no delay is resolved
            continue
        e = excitation_report(_servo_log(0.1))
        reason = get_effect(name).needs(e)
        assert reason is not None and reason.startswith("cannot tell: the sample period 100 ms resolves no"), name
    shapes = get_effect("delay").grid_for(_servo_log(7e-3))
    assert [g["delay"] for g in shapes] == [0.02]  # 2 periods = 14 ms: only the 20 ms delay


def test_a_delay_the_period_does_not_resolve_is_tested_in_its_velocity_form():
    """At 100 ms no delay of the grid is resolved: the velocity form alone is offered and the delay stays testable
    (fast motion allowed); time steps that jitter still make it untestable, saying so."""
    s = _servo_log(0.1)
    assert get_effect("delay").grid_for(s) == ({"delay": 0.0},)
    e = excitation_report(s)
    assert get_effect("delay").needs(e) is None
    reason = get_effect("delay").needs(replace(e, period_jitter=0.5))
    assert reason.startswith("cannot tell: the time steps jitter by 50 %") and "resolve a delay" in reason


def test_cogging_needs_positions_sampled_densely():
    t = np.arange(0.0, 30.0, 0.1)
    q = 0.15 * np.sign(np.sin(2 * np.pi * t / 6.5))  # holds at +-0.15 rad, 10 Hz: jumps between
    s = Signals({"t": t, "q": q, "dq": np.gradient(q, 0.1), "tau": q.copy()}, 0.1, len(t))
    e = excitation_report(s)
    assert e.position_gap > 0.2 and get_effect("cogging").needs(e).startswith("cannot tell")
    sweep = np.linspace(-1, 1, 5000)
    assert position_coverage(sweep)[0] == 0.0


def test_cogging_is_testable_from_a_densely_sampled_stretch_despite_gaps_elsewhere():
    """0.3 rad swept densely, then a fast excursion to 1 rad sampled sparsely: a ripple of known period is fitted from
    the dense stretch (2 periods of 0.04 rad, the shortest its 1 % bins resolve, fit in it); 0.05 rad is too short."""
    def report(dense_end):
        q = np.concatenate([np.linspace(0.0, dense_end, 3000), np.linspace(dense_end, 1.0, 120)])
        t = np.arange(q.size) * 0.01
        return excitation_report(Signals({"t": t, "q": q, "dq": np.gradient(q, 0.01), "tau": np.sin(t)}, 0.01, q.size))

    wide, narrow = report(0.3), report(0.05)
    assert wide.position_gap > 0.5 and wide.position_dense >= 0.28 and get_effect("cogging").needs(wide) is None
    reason = get_effect("cogging").needs(narrow)
    assert narrow.position_dense < 0.08 and "no stretch is sampled densely over 2 periods" in reason, reason
    coarse = replace(wide, position_range=(0.0, 10.0), position_gap=0.5, position_dense=0.9)  # 4 bins: 0.4 rad
    assert "cannot tell" in get_effect("cogging").needs(coarse)  # longer than the grid's longest period
    assert any(line.startswith("position range") for line in replace(wide, position_gap=None).lines())


def _servo_log(dt, seconds=None):
    seconds = seconds or max(4.0, 400 * dt)
    t = np.arange(0.0, seconds, dt)
    q = 0.3 * np.sin(2 * np.pi * 0.7 * t)
    dq = 0.3 * 2 * np.pi * 0.7 * np.cos(2 * np.pi * 0.7 * t)
    tau = 10 * np.sin(2 * np.pi * 0.3 * t)
    return Signals({"t": t, "q": q, "q_des": q + 1e-4 * tau, "dq": dq, "tau": tau}, dt, len(t))


def test_each_unit_bound_doubts_a_value_past_it_and_not_one_below():
    """Each role's bound: 2 % below it no doubt, 2 % past it one doubt naming the value and the likely unit."""
    n = 200
    ramp = np.linspace(-1.0, 1.0, n)

    def doubts(scale: float) -> list[str]:
        return unit_doubts(np.pi * TURNS * scale * ramp, MAX_ERROR * scale * ramp, MAX_TORQUE * scale * ramp,
                           MAX_PERIOD * scale, MAX_SPEED * scale * ramp, MAX_TORQUE * scale * ramp)

    assert doubts(0.98) == []
    past = doubts(1.02)
    assert len(past) == 6
    for hint in ("milliseconds", "degrees?", "deg/s?", "the torque reaches", "the torque target reaches"):
        assert any(hint in d for d in past), hint


def test_a_position_of_white_noise_is_a_fault_and_a_sampled_motion_is_not():
    rng = np.random.default_rng(3)
    t = np.arange(2000) * 0.02  # 20 ms: the coarsest period the workbench is built for
    motion = 0.5 * np.sin(2 * np.pi * 2.0 * t)
    assert position_noise_fault(motion + rng.normal(0, 1e-3, t.size)) is None
    fault = position_noise_fault(rng.normal(0, 0.1, t.size))
    assert fault is not None and "the position is mostly noise" in fault
