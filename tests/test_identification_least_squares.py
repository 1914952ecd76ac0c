"""Tests of servotau.identification.least_squares (paper eq. 7)."""

import numpy as np
import pytest

from servotau.errors import IdentificationError
from servotau.identification import Regressors, fit_least_squares, fit_linear_model, linear_regressors


def exact_data(m=200, seed=0):
    rng = np.random.default_rng(seed)
    tau = rng.uniform(-40, 40, m)  # [N m]
    dq = rng.uniform(-1.5, 1.5, m)  # [rad/s]
    return tau, dq


def test_recovers_exact_linear_model():
    """Noise-free data of dq_err = k_tau tau + k_v dq give back k_tau and k_v to 1e-9 relative."""
    tau, dq = exact_data()
    fit = fit_linear_model(tau, dq, 2.12e-4 * tau + 0.013 * dq)
    assert fit.coefficients["k_tau"] == pytest.approx(2.12e-4, rel=1e-9)
    assert fit["k_v"] == pytest.approx(0.013, rel=1e-9)
    assert fit.rms < 1e-15 and fit.n_samples == 200 and fit.solver == "lstsq"
    assert 1.0 <= fit.condition_number < 10.0


def test_recovers_exact_model_with_coulomb():
    """With coulomb=True the sign(dq) column (zero at dq == 0) gives back k_c exactly too."""
    tau, dq = exact_data()
    dq[::10] = 0.0
    fit = fit_linear_model(tau, dq, 1e-4 * tau + 0.007 * dq + 5e-4 * np.sign(dq), coulomb=True)
    assert fit.names == ("k_tau", "k_v", "k_c")
    np.testing.assert_allclose(fit.x, [1e-4, 0.007, 5e-4], rtol=1e-9)


def test_general_named_columns_and_offset():
    """A regressor with custom named columns is fitted as A x + offset = b, coefficients keyed by name."""
    rng = np.random.default_rng(1)
    a = rng.standard_normal((100, 2))
    offset = rng.standard_normal(100)
    fit = fit_least_squares(Regressors(("p", "q"), a), a @ [3.0, -2.0] + offset, offset=offset)
    assert fit.coefficients == pytest.approx({"p": 3.0, "q": -2.0}, rel=1e-12)
    np.testing.assert_allclose(fit.predict(Regressors(("p", "q"), a)), a @ [3.0, -2.0], rtol=1e-9, atol=1e-12)


def test_a_constant_column_named_as_constant_is_fitted_as_an_offset():
    """Through fit_with_loss, as the asymmetric fit: a column of ones named in ``constant`` is fitted (an exact
    model with a 3e-4 rad offset comes back to 1e-9); not named, it is refused as unexcited."""
    from servotau.identification import Loss, fit_with_loss

    tau, dq = exact_data()
    a = Regressors(("k_tau", "k_v", "offset"), np.column_stack([tau, dq, np.ones_like(tau)]))
    y = 2.12e-4 * tau + 0.013 * dq + 3e-4
    fit = fit_with_loss(a, y, Loss.least_squares(), constant=("offset",))
    np.testing.assert_allclose(fit.x, [2.12e-4, 0.013, 3e-4], rtol=1e-9)
    with pytest.raises(IdentificationError, match="column 'offset' is constant"):
        fit_least_squares(a, y)


def test_least_squares_is_the_minimiser():
    """On noisy data the fit equals numpy's lstsq solution (no bias from the internal scaling)."""
    tau, dq = exact_data(500, seed=3)
    b = 2e-4 * tau + 0.01 * dq + 1e-3 * np.random.default_rng(3).standard_normal(500)
    fit = fit_least_squares(linear_regressors(tau, dq), b)
    ref, *_ = np.linalg.lstsq(np.column_stack([tau, dq]), b, rcond=None)
    np.testing.assert_allclose(fit.x, ref, rtol=1e-10)


def test_collinear_columns_refused():
    """Proportional torque and velocity (rank-deficient regressor) raise, naming the columns."""
    tau, _ = exact_data()
    with pytest.raises(IdentificationError, match=r"\['k_tau', 'k_v'\] are linearly dependent"):
        fit_linear_model(tau, 0.01 * tau, tau)
