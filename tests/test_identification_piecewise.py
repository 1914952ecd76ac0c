"""Tests of servotau.identification.piecewise (paper section 3.2.2)."""

import math

import numpy as np
import pytest

from servotau.errors import IdentificationError
from servotau.identification import fit_piecewise, fit_piecewise_1d


def three_lines(tau, t1, t2, k1, k2, k3, q2):
    """A continuous piecewise-linear function with breakpoints t1 < t2."""
    middle = k2 * tau + q2
    left = k2 * t1 + q2 + k1 * (tau - t1)
    right = k2 * t2 + q2 + k3 * (tau - t2)
    return np.where(tau < t1, left, np.where(tau > t2, right, middle))


POS = dict(t1=-1.2, t2=0.8, k1=2e-4, k2=3e-3, k3=1.5e-4, q2=1e-3)
NEG = dict(t1=-0.7, t2=1.5, k1=1.8e-4, k2=2e-3, k3=2.2e-4, q2=-1e-3)


def piecewise_data(m=4000, seed=0):
    rng = np.random.default_rng(seed)
    tau = rng.uniform(-20, 20, m)  # [N m]
    dq = rng.choice([-1.0, 1.0], m) * rng.uniform(0.01, 1.0, m)  # [rad/s]
    dq_err = np.where(dq > 0, three_lines(tau, **POS), three_lines(tau, **NEG))
    return tau, dq, dq_err


def test_recovers_known_breakpoints_per_velocity_sign():
    """From the default guess (-0.5, 0.5) N m, the breakpoints and lines of each sign are recovered."""
    tau, dq, dq_err = piecewise_data()
    fit = fit_piecewise(tau, dq, dq_err, k2_bounds=(1e-3, 1e-2))
    for model, truth in ((fit.positive, POS), (fit.negative, NEG)):
        np.testing.assert_allclose(model.breakpoints, (truth["t1"], truth["t2"]), rtol=1e-9)
        np.testing.assert_allclose(model.slopes, (truth["k1"], truth["k2"], truth["k3"]), rtol=1e-9)
        assert model.converged and 1 < model.iterations <= 10
        assert model.breakpoint_history[0] == (-0.5, 0.5)
        assert model.breakpoint_history[-1] == model.breakpoints
        assert model.rms < 1e-12
    assert fit.converged
    np.testing.assert_allclose(fit.evaluate(tau, dq), dq_err, atol=1e-12)


def test_continuous_at_breakpoints():
    """On noisy data the fitted function is continuous: both adjacent lines agree at each breakpoint."""
    tau, dq, dq_err = piecewise_data(seed=1)
    dq_err = dq_err + 2e-4 * np.random.default_rng(1).standard_normal(tau.size)
    fit = fit_piecewise(tau, dq, dq_err, k2_bounds=(1e-3, 1e-2))
    for model in (fit.positive, fit.negative):
        (k1, k2, k3), (q1, q2, q3) = model.slopes, model.intercepts
        t1, t2 = model.breakpoints
        assert k1 * t1 + q1 == pytest.approx(k2 * t1 + q2, abs=1e-15)
        assert k2 * t2 + q2 == pytest.approx(k3 * t2 + q3, abs=1e-15)
        eps = 1e-9
        assert abs(model(t1 - eps) - model(t1 + eps)) < 1e-10
        assert abs(model(t2 - eps) - model(t2 + eps)) < 1e-10


def test_middle_slope_bounded():
    """The middle slope stays within [k2_min, k2_max] even when the data want a steeper one."""
    tau, dq, dq_err = piecewise_data(seed=2)
    fit = fit_piecewise(tau, dq, dq_err, k2_bounds=(1e-3, 1.5e-3))
    assert 1e-3 <= fit.positive.slopes[1] <= 1.5e-3
    assert fit.positive.slopes[1] == 1.5e-3


def test_evaluate_at_zero_velocity_is_mean():
    """At dq == 0 the model is the mean of the two sign models."""
    tau, dq, dq_err = piecewise_data(seed=3)
    fit = fit_piecewise(tau, dq, dq_err, k2_bounds=(1e-3, 1e-2))
    t = np.array([-5.0, 0.1, 5.0])
    np.testing.assert_allclose(fit.evaluate(t, 0.0), 0.5 * (fit.positive(t) + fit.negative(t)))


def test_not_converged_is_reported_or_raised():
    """With max_iterations=1 the fit reports converged=False, and strict=True raises instead."""
    tau, dq, dq_err = piecewise_data(seed=4)
    fit = fit_piecewise_1d(tau[dq > 0], dq_err[dq > 0], max_iterations=1, k2_bounds=(1e-3, 1e-2))
    assert not fit.converged and fit.iterations == 1 and len(fit.breakpoint_history) == 2
    with pytest.raises(IdentificationError, match="max_iterations = 1"):
        fit_piecewise_1d(tau[dq > 0], dq_err[dq > 0], max_iterations=1, strict=True)


def test_bad_settings_and_segments_raise():
    """Breakpoints outside the data, unordered breakpoints, one-sided motion raise, naming the input."""
    tau, dq, dq_err = piecewise_data(m=300, seed=5)
    with pytest.raises(IdentificationError, match=r"segment 3 .* expected at least 3"):
        fit_piecewise_1d(tau, dq_err, breakpoints=(-1.0, 50.0))
    with pytest.raises(IdentificationError, match=r"breakpoints = \(1.0, -1.0\): expected finite tau_1 < tau_2"):
        fit_piecewise_1d(tau, dq_err, breakpoints=(1.0, -1.0))
    with pytest.raises(IdentificationError, match=r"k2_bounds"):
        fit_piecewise_1d(tau, dq_err, k2_bounds=(1.0, 0.0))
    with pytest.raises(IdentificationError, match=r"dq: no sample with dq < 0"):
        fit_piecewise(tau, np.abs(dq), dq_err)
    with pytest.raises(IdentificationError, match=r"tau: 1 of 300 samples are NaN"):
        fit_piecewise(np.where(np.arange(300) == 7, math.nan, tau), dq, dq_err)
