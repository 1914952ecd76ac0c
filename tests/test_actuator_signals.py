"""actuator/signals.py: derived signals computed once per dataset and its copies; filters with memory restart at each
run of the log."""

import numpy as np
import pytest

from servotau.actuator.friction_state import state, steps, strokes
from servotau.actuator.signals import (
    Signals,
    acceleration,
    advanced,
    bell_of,
    command_lead,
    delayed,
    direction_latch,
    hysteresis,
    inertia,
    lowpass,
    run_onsets,
    sign_latch,
    sign_of,
    since_onset,
    smooth_sign,
)
from servotau.errors import IdentificationError


def test_derived_is_computed_once_for_a_signals_and_its_copies_and_again_for_another_source():
    """A filter of q runs once across with_columns copies (a diagnosis refits many models on one q); a copy
    with another q gets its own result; results are read-only."""
    calls = []

    def double(x):
        calls.append(1)
        return 2.0 * x

    s = Signals({"q": np.arange(5.0), "u": np.zeros(5)}, 1e-3, 5)
    a = s.derived("q", ("double",), double)
    copy = s.with_columns(u=np.ones(5))
    assert copy.derived("q", ("double",), double) is a and len(calls) == 1
    other = s.with_columns(q=np.arange(5.0) + 1.0)
    np.testing.assert_array_equal(other.derived("q", ("double",), double), 2.0 * (np.arange(5.0) + 1.0))
    assert len(calls) == 2
    with pytest.raises(ValueError):
        a[0] = 1.0


def test_the_sign_and_bell_of_dq_are_those_of_the_formula_once_per_width():
    """The friction terms' sign(dq) and exp(-(dq / v)^2): the formula's numbers, kept for the copies a fit makes
    (with another u), one per width, computed again for another dq."""
    dq = np.linspace(-0.1, 0.1, 41)
    s = Signals({"dq": dq, "u": np.zeros(41)}, 1e-3, 41)
    a, b = sign_of(s, "dq", 0.01), bell_of(s, "dq", 0.02)
    np.testing.assert_array_equal(a, smooth_sign(dq, 0.01))
    np.testing.assert_array_equal(b, np.exp(-((dq / 0.02) ** 2)))
    copy = s.with_columns(u=np.ones(41))
    assert sign_of(copy, "dq", 0.01) is a and bell_of(copy, "dq", 0.02) is b
    np.testing.assert_array_equal(sign_of(s, "dq", 0.0), np.sign(dq))
    assert not np.array_equal(sign_of(s, "dq", 0.05), a)
    np.testing.assert_array_equal(sign_of(s.with_columns(dq=-dq), "dq", 0.01), -a)


# -- runs: every filter with memory restarts at each start (hand-computed) -----------------------------------------

STARTS = (0, 3)


def test_signals_carry_their_runs_into_copies_and_check_them():
    s = Signals({"q": np.zeros(6)}, 1e-3, 6, starts=STARTS)
    assert s.with_columns(u=np.ones(6)).starts == STARTS and s.runs() == [(0, 3), (3, 6)]
    assert Signals({"q": np.zeros(6)}, 1e-3, 6).runs() == [(0, 6)]
    for bad in ((1, 3), (0, 3, 3), (0, 6), ()):
        with pytest.raises(IdentificationError, match="starts"):
            Signals({"q": np.zeros(6)}, 1e-3, 6, starts=bad)


def test_delayed_and_the_command_lead_repeat_each_runs_first_value():
    x = np.array([1.0, 2.0, 3.0, 10.0, 20.0, 30.0])
    np.testing.assert_array_equal(delayed(x, 1, STARTS), [1, 1, 2, 10, 10, 20])
    np.testing.assert_array_equal(delayed(x, 5, STARTS), [1, 1, 1, 10, 10, 10])
    np.testing.assert_array_equal(delayed(x, 1), [1, 1, 2, 3, 10, 20])  # one run: across the join
    s = Signals({"q_des": x, "q": np.full(6, 0.5)}, 1e-3, 6, starts=STARTS)
    np.testing.assert_array_equal(command_lead(s), [0.5, 0.5, 1.5, 9.5, 9.5, 19.5])


def test_lowpass_restarts_from_its_initial_value_at_each_run():
    x = np.array([2.0, 0.0, 0.0, 4.0, 0.0, 0.0])  # time constant = dt: gain 1/2
    np.testing.assert_allclose(lowpass(x, 1e-3, 1e-3, starts=STARTS), [2, 1, 0.5, 4, 2, 1])
    np.testing.assert_allclose(lowpass(x, 1e-3, 1e-3, y0=0.0, starts=STARTS), [1, 0.5, 0.25, 2, 1, 0.5])
    np.testing.assert_allclose(lowpass(x, 1e-3, 1e-3), [2, 1, 0.5, 2.25, 1.125, 0.5625])


def test_many_runs_give_what_each_run_alone_gives():
    """A log with thousands of gaps (rows dropped for NaN) is filtered in one pass, not run by run: the result is
    each run's own, from a loop over the runs with one-run calls (runs of 1 to 12 samples)."""
    rng = np.random.default_rng(7)
    lengths = rng.integers(1, 13, 800)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    n = int(lengths.sum())
    x = rng.normal(0, 1, n)
    flag = rng.random(n) < 0.3

    def each(f, *xs):
        return np.concatenate([f(*(v[a:a + m] for v in xs)) for a, m in zip(starts, lengths, strict=True)])

    for k in (1, 3, 20):
        np.testing.assert_array_equal(delayed(x, k, starts), each(lambda v, k=k: delayed(v, k), x))
        np.testing.assert_array_equal(advanced(x, k, starts), each(lambda v, k=k: advanced(v, k), x))
    np.testing.assert_array_equal(sign_latch(x, flag, starts), each(sign_latch, x, flag))
    for tc, y0 in ((1e-3, None), (0.05, None), (0.05, 0.3)):
        alone = each(lambda v, tc=tc, y0=y0: lowpass(v, tc, 1e-3, y0), x)
        np.testing.assert_allclose(lowpass(x, tc, 1e-3, y0, starts), alone, rtol=0, atol=1e-12)
    v = 0.05 * np.quantile(np.abs(x), 0.95)

    def run_strokes(d):  # travel from the run's first move to each reversal, and from the last one to its end
        moves = np.flatnonzero(np.abs(d) > v)
        if moves.size < 2:
            return np.zeros(0)
        flips = [k for a, k in zip(moves, moves[1:], strict=False) if np.sign(d[a]) != np.sign(d[k])]
        edges = [moves[0], *flips, len(d)]
        return np.array([np.abs(d[a:b]).sum() * 1e-3 for a, b in zip(edges, edges[1:], strict=False)])

    np.testing.assert_allclose(strokes(x, 1e-3, starts), each(run_strokes, x), rtol=1e-9)


def test_latches_onsets_and_the_hysteresis_detector_start_afresh_in_each_run():
    dq = np.array([0.5, 0.0, 0.0, 0.0, -0.5, 0.0])
    np.testing.assert_array_equal(direction_latch(dq, 0.1, STARTS), [1, 1, 1, 0, -1, -1])
    np.testing.assert_array_equal(direction_latch(dq, 0.1), [1, 1, 1, 1, -1, -1])
    np.testing.assert_array_equal(sign_latch(dq, np.abs(dq) > 0.1, STARTS), [1, 1, 1, 0, -1, -1])
    on = np.ones(6, dtype=bool)
    np.testing.assert_array_equal(run_onsets(on, STARTS), [0, 0, 0, 3, 3, 3])
    np.testing.assert_array_equal(since_onset(np.arange(6.0), on, STARTS), [0, 1, 2, 0, 1, 2])
    np.testing.assert_array_equal(since_onset(np.arange(6.0), on), [0, 1, 2, 3, 4, 5])
    x = np.array([2.0, 0.9, 0.9, 0.9, 2.0, 0.9])  # on at 1, off at 0.5: the second run starts off
    np.testing.assert_array_equal(hysteresis(x, 1.0, 0.5, STARTS), [1, 1, 1, 0, 1, 1])
    np.testing.assert_array_equal(hysteresis(x, 1.0, 0.5), [1, 1, 1, 1, 1, 1])


def test_the_acceleration_is_fitted_on_each_run_one_sided_at_its_edges():
    """q = t^2 / 2 then, after the join, 5 - t^2: the cubic SG fit is exact on each run (ddq = 1, then -2), up to
    the join's samples, which a fit across the join gets wrong; the delayed inertia repeats the run's first value."""
    dt, n1, n2 = 0.01, 20, 15
    t1, t2 = np.arange(n1) * dt, np.arange(n2) * dt
    q = np.concatenate([0.5 * t1 ** 2, 5.0 - t2 ** 2])
    s = Signals({"q": q, "ddq": np.zeros(n1 + n2)}, dt, n1 + n2, starts=(0, n1))
    expected = np.concatenate([np.ones(n1), np.full(n2, -2.0)])
    np.testing.assert_allclose(acceleration(s, 7 * dt), expected, atol=1e-6)
    across = acceleration(Signals({"q": q}, dt, n1 + n2), 7 * dt)
    assert np.max(np.abs(across - expected)) > 1e3  # what the join did before
    np.testing.assert_allclose(inertia(s, 7 * dt, 2 * dt), delayed(expected, 2, (0, n1)), atol=1e-6)
    # a run shorter than the window takes the data's own ddq there
    short = Signals({"q": q, "ddq": np.full(n1 + n2, 7.0)}, dt, n1 + n2, starts=(0, n1, n1 + 3))
    np.testing.assert_allclose(acceleration(short, 7 * dt)[n1:n1 + 3], 7.0)


def test_the_friction_state_restarts_from_zero_with_the_runs_own_velocity():
    dt, x0 = 1e-3, 1e-3
    dq = np.array([1.0, 1.0, 1.0, -2.0, -2.0])
    s = Signals({"dq": dq}, dt, 5, starts=STARTS)
    z = state(s, "test", x0)
    a, b = steps(np.array([-2.0]), dt, x0)  # the run's first tick: its own velocity, from z = 0
    assert z[3] == pytest.approx(b[0]) and z[3] == pytest.approx(-(1 - np.exp(-2.0)))
    assert z[4] == pytest.approx(a[0] * z[3] + b[0])
    alone = [state(Signals({"dq": dq[i:j]}, dt, j - i), "test", x0) for i, j in ((0, 3), (3, 5))]
    np.testing.assert_array_equal(z, np.concatenate(alone))
