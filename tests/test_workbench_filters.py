"""SG filters chosen from the data (identification/workbench/filters.py): the window and the derivative's order."""

from __future__ import annotations

import numpy as np
from support.synthetic import two_sine_log

from servotau.identification.workbench.filters import cv_derivative, cv_window


def _runs(n):
    return [(0, n)]


def test_cv_window_shorter_when_faster_sampled_on_a_smooth_signal():
    # the same smooth signal with the same little noise: the faster-sampled log gets a shorter window in time
    fast, slow = two_sine_log(1e-3, 2e-6), two_sine_log(8e-3, 2e-6, duration=32.0)
    w_fast = cv_window(fast["q"], _runs(len(fast["q"])))
    w_slow = cv_window(slow["q"], _runs(len(slow["q"])))
    assert w_fast * 1e-3 < w_slow * 8e-3
    assert w_fast * 1e-3 < 0.041  # shorter than the former fixed window


def test_cv_window_longer_on_a_noisier_signal():
    quiet, noisy = two_sine_log(1e-3, 1e-6), two_sine_log(1e-3, 1e-3)
    assert cv_window(noisy["q"], _runs(len(noisy["q"]))) > cv_window(quiet["q"], _runs(len(quiet["q"])))


def _sines(dt, noise, f, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 20.0, dt)
    return 0.3 * np.sin(2 * np.pi * f * t) + 0.1 * np.sin(2 * np.pi * 0.37 * f * t) + rng.normal(0.0, noise, t.size)


def test_the_quartic_derivative_is_chosen_for_fast_motion_over_few_samples():
    """2 Hz at 9 ms, nearly noise-free: the order-2 fit bends too little within its window, the quartic predicts the
    held-out samples better, over a longer window than the order-2 one would take."""
    q = _sines(9e-3, 1e-6, 2.0)
    window, order = cv_derivative(q, _runs(q.size))
    assert order == 4 and window == cv_window(q, _runs(q.size), 4) > cv_window(q, _runs(q.size), 2)


def test_the_order_2_derivative_is_kept_for_slow_noisy_motion():
    """Slow motion under encoder noise: both orders reach the longest window, where the order-2 fit averages more
    noise away."""
    for dt, noise, f in ((1e-3, 1e-3, 0.3), (2e-3, 1e-3, 0.05)):
        q = _sines(dt, noise, f)
        assert cv_derivative(q, _runs(q.size)) == (cv_window(q, _runs(q.size), 2), 2)
