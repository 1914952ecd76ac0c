"""Tests of servotau.identification.fit (one entry point for both losses)."""

import numpy as np

from servotau.identification import (
    Loss,
    fit_asymmetric,
    fit_least_squares,
    fit_linear_model,
    linear_regressors,
    make_synthetic,
)


def test_dispatch_matches_direct_calls():
    """fit_linear_model with each loss equals the direct least-squares and asymmetric fits."""
    d = make_synthetic(500, seed=0)
    a = linear_regressors(d.tau, d.dq)
    np.testing.assert_array_equal(fit_linear_model(d.tau, d.dq, d.dq_err).x, fit_least_squares(a, d.dq_err).x)
    asym = fit_linear_model(d.tau, d.dq, d.dq_err, loss=Loss.asymmetric(7.0))
    np.testing.assert_array_equal(asym.x, fit_asymmetric(a, d.dq_err, 7.0).x)
    assert asym.loss == Loss.asymmetric(7.0) and asym.solver == "newton"
