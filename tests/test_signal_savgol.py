"""Tests of servotau.signal.savgol."""

import math
import tracemalloc

import numpy as np
import pytest

from servotau.errors import EstimationError
from servotau.signal.savgol import (
    FEW_RUNS,
    CausalSavgol,
    causal_coeffs,
    delay,
    savgol_centred,
    savgol_centred_runs,
    savgol_coeffs,
)

DT = 1e-3  # [s]


def poly_and_derivs(coefs: np.ndarray, t: np.ndarray) -> list[np.ndarray]:
    """Values of a polynomial (numpy.polynomial order) and of its first two derivatives at t."""
    p = np.polynomial.Polynomial(coefs)
    return [p(t), p.deriv(1)(t), p.deriv(2)(t)]


def test_coefficients_are_scipys():
    """savgol_coeffs solves scipy.signal.savgol_coeffs' problem with its solver: the same numbers (equal to the bit
    with scipy 1.17; to 1e-10 here, so that another scipy release's round-off does not fail the suite), for windows
    1 .. 201, orders 0 .. 5, every derivative and both uses."""
    from scipy.signal import savgol_coeffs as scipy_coeffs

    n = 0
    for window in (1, 2, 3, 4, 5, 8, 13, 21, 41, 80, 81, 201):
        for order in range(min(window, 6)):
            for deriv in range(order + 2):  # deriv > order: zeros
                for pos in (None, 0.0, (window - 1) / 2, float(window - 1), float(window // 3)):
                    for use in ("dot", "conv"):
                        for delta in (1.0, 1.3e-3):
                            want = scipy_coeffs(window, order, deriv=deriv, delta=delta, pos=pos, use=use)
                            got = savgol_coeffs(window, order, deriv, delta, pos, use)
                            assert np.allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max()), \
                                (window, order, deriv, pos, use, delta)
                            n += 1
    assert n > 2_000


@pytest.mark.parametrize("eval_at", ["last", "centre"])
@pytest.mark.parametrize("window", [7, 80])
@pytest.mark.parametrize("order", [1, 2, 3])
def test_causal_exact_on_polynomials(eval_at, window, order):
    """Causal value, 1st and 2nd derivatives are exact on polynomials of degree <= order."""
    rng = np.random.default_rng(order)
    derivs = tuple(range(min(order, 2) + 1))
    n_samples = window + 13
    t = np.arange(n_samples) * DT  # [s]
    coefs = rng.standard_normal((3, order + 1)) * 10.0 ** -np.arange(order + 1)
    signals = [poly_and_derivs(c, t) for c in coefs]
    sg = CausalSavgol(3, window, order, DT, derivs=derivs, eval_at=eval_at)
    for i in range(n_samples):
        sg.update(np.array([s[0][i] for s in signals]))
    t_eval = t[-1] - (window - 1 - (window - 1 if eval_at == "last" else (window - 1) / 2)) * DT
    for k, out in zip(derivs, sg.outputs, strict=True):
        expected = np.array([np.polynomial.Polynomial(c).deriv(k)(t_eval) for c in coefs])
        np.testing.assert_allclose(out, expected, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_centred_exact_on_polynomials(order):
    """Off-line centred value and derivatives equal the polynomial's at every time stamp, edges included."""
    t = np.arange(500) * DT - 0.2  # [s]
    coefs = np.array([0.3, -1.0, 2.0, -4.0])[: order + 1]
    values = poly_and_derivs(coefs, t)
    x = np.column_stack([values[0], 2.0 * values[0]])
    for k in range(min(order, 2) + 1):
        y = savgol_centred(x, 81, order, DT, deriv=k)
        assert y.shape == x.shape
        np.testing.assert_allclose(y[:, 0], values[k], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(y[:, 1], 2.0 * values[k], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(savgol_centred(values[0], 81, order, DT), values[0], atol=1e-9)


@pytest.mark.parametrize(("window", "order", "deriv"), [(5, 2, 1), (11, 2, 1), (9, 3, 2), (13, 4, 0)])
def test_runs_in_one_pass_equal_the_filter_run_by_run(window, order, deriv):
    """Runs of the window's length up to hundreds of samples, more than FEW_RUNS so that they are filtered in one
    pass: each run's result is that of savgol_centred on the run alone (edges included); samples outside the runs
    keep their value."""
    rng = np.random.default_rng(window)
    x = rng.normal(size=900 + 30 * FEW_RUNS)
    runs = np.array([[0, 40], [40, 40 + window], [60, 300], [300, 313 + window], [400, 900],
                     *([900 + 30 * i, 900 + 30 * i + window + i % 7] for i in range(FEW_RUNS))])
    out = savgol_centred_runs(x, runs, window, order, DT, deriv, out=np.full_like(x, 7.0))
    for a, b in runs:
        ref = savgol_centred(x[a:b], window, order, DT, deriv=deriv)
        np.testing.assert_allclose(out[a:b], ref, rtol=0, atol=1e-9 * np.max(np.abs(ref)))
    assert np.all(out[313 + window:400] == 7.0)
    np.testing.assert_array_equal(savgol_centred_runs(x, np.zeros((0, 2)), window, order, DT, deriv), 0.0)
    with pytest.raises(EstimationError, match="a run shorter than window"):
        savgol_centred_runs(x, np.array([[0, window - 1]]), window, order, DT, deriv)


def test_ring_buffer_matches_direct_dot():
    """After many wrap-arounds each update equals the coefficients dotted with the last N samples."""
    window, order, derivs = 80, 2, (0, 1, 2)
    x = np.random.default_rng(1).standard_normal((1000, 5))
    sg = CausalSavgol(5, window, order, DT, derivs=derivs, eval_at="last")
    coeffs = [causal_coeffs(window, order, k, DT, "last") for k in derivs]
    for i, sample in enumerate(x):
        sg.update(sample)
        if i + 1 >= window:
            for c, out in zip(coeffs, sg.outputs, strict=True):
                np.testing.assert_allclose(out, c @ x[i + 1 - window : i + 1], rtol=1e-12, atol=1e-9)


def test_not_ready_before_window():
    """Outputs are NaN and ready is False until window samples are accepted, and again after reset."""
    sg = CausalSavgol(2, 10, 1, DT, derivs=(0, 1))
    for _ in range(9):
        sg.update(np.ones(2))
        assert not sg.ready
        assert all(np.isnan(out).all() for out in sg.outputs)
    sg.update(np.ones(2))
    assert sg.ready
    np.testing.assert_allclose(sg.output(0), 1.0)
    np.testing.assert_allclose(sg.output(1), 0.0, atol=1e-9)
    sg.reset()
    assert not sg.ready and np.isnan(sg.output(0)).all()


def test_nan_sample_rejected_and_buffer_unchanged():
    """A NaN sample raises EstimationError naming x and leaves buffer and outputs as they were."""
    sg = CausalSavgol(3, 10, 2, DT, derivs=(0, 1))
    ref = CausalSavgol(3, 10, 2, DT, derivs=(0, 1))
    x = np.random.default_rng(2).standard_normal((30, 3))
    for sample in x[:20]:
        sg.update(sample)
        ref.update(sample)
    before = [out.copy() for out in sg.outputs]
    with pytest.raises(EstimationError, match=r"x is NaN or inf at channels \[1\]"):
        sg.update(np.array([0.0, np.nan, 0.0]))
    for b, out in zip(before, sg.outputs, strict=True):
        np.testing.assert_array_equal(out, b)
    for sample in x[20:]:
        sg.update(sample)
        ref.update(sample)
    for a, b in zip(sg.outputs, ref.outputs, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"window": 2.5}, "window"),
        ({"window": 0}, "window"),
        ({"order": -1}, "order"),
        ({"order": 80}, "order"),
        ({"dt": 0.0}, "dt"),
        ({"dt": math.nan}, "dt"),
        ({"derivs": (0, 3)}, "derivs"),
        ({"derivs": ()}, "derivs"),
        ({"derivs": (1, 1)}, "derivs"),
        ({"eval_at": "middle"}, "eval_at"),
        ({"n_channels": 0}, "n_channels"),
    ],
)
def test_bad_arguments_raise(kwargs, name):
    """Invalid settings raise EstimationError whose message names the argument."""
    settings = {"n_channels": 3, "window": 80, "order": 2, "dt": DT, "derivs": (0, 1, 2), "eval_at": "last"}
    with pytest.raises(EstimationError, match=name):
        CausalSavgol(**(settings | kwargs))


def test_bad_arguments_raise_off_line_and_update():
    """Wrong sample shape, even centred window, deriv > order, short x: errors name the argument."""
    sg = CausalSavgol(3, 80, 2, DT)
    with pytest.raises(EstimationError, match="x has shape"):
        sg.update(np.zeros(4))
    with pytest.raises(EstimationError, match="window"):
        savgol_centred(np.zeros(200), 80, 2, DT)
    with pytest.raises(EstimationError, match="deriv"):
        savgol_centred(np.zeros(200), 81, 1, DT, deriv=2)
    with pytest.raises(EstimationError, match="x has 50 samples"):
        savgol_centred(np.zeros(50), 81, 1, DT)
    with pytest.raises(EstimationError, match="deriv"):
        delay(80, 1, 2)
    assert isinstance(EstimationError("x"), ValueError)


def test_delay_closed_form():
    """delay() is (N-1)/2 when deriv == order, else N-1-pos: 0 at the last sample, (N-1)/2 at the centre."""
    for window in (7, 80):
        for order in (0, 1, 2):
            for k in range(order + 1):
                assert delay(window, order, k, "centre") == (window - 1) / 2
                assert delay(window, order, k, "last") == ((window - 1) / 2 if k == order else 0.0)


@pytest.mark.parametrize("eval_at", ["last", "centre"])
@pytest.mark.parametrize(("order", "deriv"), [(0, 0), (1, 0), (1, 1), (2, 0), (2, 1), (2, 2)])
def test_measured_delay_on_slow_sine(eval_at, order, deriv):
    """The phase lag of the causal filter on a slow sine, expressed in samples, equals delay()."""
    window = 80
    omega = 2 * math.pi * 0.5  # [rad/s], period 2000 samples
    n_samples = 4000
    t = np.arange(n_samples) * DT
    sg = CausalSavgol(1, window, order, DT, derivs=(deriv,), eval_at=eval_at)
    y = np.empty(n_samples)
    for i in range(n_samples):
        sg.update(np.array([math.sin(omega * t[i])]))
        y[i] = sg.outputs[0][0]
    # Fit y = a sin(omega t) + b cos(omega t) on the ready part and read the phase lag.
    ready = slice(window, None)
    basis = np.column_stack([np.sin(omega * t[ready]), np.cos(omega * t[ready])])
    a, b = np.linalg.lstsq(basis, y[ready], rcond=None)[0]
    lag = (deriv * math.pi / 2 - math.atan2(b, a)) % (2 * math.pi)  # [rad]
    lag = (lag + math.pi) % (2 * math.pi) - math.pi
    assert lag / omega / DT == pytest.approx(delay(window, order, deriv, eval_at), abs=0.5)


def test_no_allocation_per_update():
    """1000 updates allocate no memory and the output arrays keep their identity."""
    sg = CausalSavgol(30, 80, 2, DT, eval_at="centre")
    samples = np.random.default_rng(3).standard_normal((200, 30))
    rows = list(samples)
    outputs = sg.outputs
    ids = [id(out) for out in outputs]
    for row in rows:
        sg.update(row)
    tracemalloc.start()
    try:
        start, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for i in range(1000):
            sg.update(rows[i % 200])
        end, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert end - start < 1024
    assert peak - start < 4096
    assert [id(out) for out in sg.outputs] == ids
    assert all(not out.flags.writeable for out in outputs)
    last = np.array([rows[i % 200] for i in range(920, 1000)])
    np.testing.assert_allclose(outputs[0], causal_coeffs(80, 2, 0, DT, "centre") @ last)
