"""Tests of servotau.identification.synthetic."""

import numpy as np

from servotau.identification import make_synthetic


def test_synthetic_data_follow_the_model():
    """Noise-free data equal the stated model, with the asked static fraction at dq == 0 exactly."""
    d = make_synthetic(5000, seed=1, noise=0.0, static_fraction=0.3)
    np.testing.assert_array_equal(d.dq_err, d.truth)
    assert abs(np.mean(d.dq == 0.0) - 0.3) < 0.03
    assert np.all((np.abs(d.dq) >= 0.05) | (d.dq == 0.0))
    expected = 2.12e-4 * d.tau + 0.013 * d.dq + 5e-4 * np.sign(d.dq) + 2e-3 * np.clip(d.tau, -1, 1)
    np.testing.assert_allclose(d.truth, expected, rtol=1e-12)
