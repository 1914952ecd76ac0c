"""Tests of servotau.identification.asymmetric and asymmetric_qp (paper eq. 8-9)."""

import numpy as np
import pytest

from servotau.errors import IdentificationError
from servotau.identification import (
    Regressors,
    asymmetric_cost,
    fit_asymmetric,
    fit_least_squares,
    linear_regressors,
    make_synthetic,
    overestimation_rate,
)


def test_newton_recovers_exact_linear_model():
    """Noise-free linear data are recovered to 1e-9 by the Newton method (zero residual, any w)."""
    rng = np.random.default_rng(0)
    tau, dq = rng.uniform(-40, 40, 300), rng.uniform(-1.5, 1.5, 300)
    fit = fit_asymmetric(linear_regressors(tau, dq), 2.12e-4 * tau + 0.013 * dq, w=10.0)
    np.testing.assert_allclose(fit.x, [2.12e-4, 0.013], rtol=1e-9)
    assert fit.status == "solved" and fit.loss.w == 10.0


def test_newton_and_osqp_agree_on_noisy_nonlinear_data():
    """Newton and the OSQP QP of eq. 9 give the same coefficients to 1e-6 relative (m = 2000, dead zone)."""
    d = make_synthetic(2000, seed=1)
    a = linear_regressors(d.tau, d.dq, coulomb=True)
    newton = fit_asymmetric(a, d.dq_err, 10.0, solver="newton")
    qp = fit_asymmetric(a, d.dq_err, 10.0, solver="osqp")
    np.testing.assert_allclose(qp.x, newton.x, rtol=1e-6)
    assert qp.status == "solved" and qp.solve_time_s > 0.0 and qp.iterations > 0


def test_newton_is_the_minimiser():
    """The Newton solution has a lower eq. 8 cost than small perturbations of it (global minimum)."""
    d = make_synthetic(1000, seed=2)
    a = linear_regressors(d.tau, d.dq)
    fit = fit_asymmetric(a, d.dq_err, 5.0)
    best = asymmetric_cost(a.matrix @ fit.x - d.dq_err, d.dq_err, 5.0)
    for dx in np.random.default_rng(2).standard_normal((20, 2)):
        x = fit.x * (1.0 + 1e-4 * dx)
        assert asymmetric_cost(a.matrix @ x - d.dq_err, d.dq_err, 5.0) > best


def test_a_constant_column_named_as_constant_is_fitted_as_an_offset():
    """A column of ones named in ``constant`` is fitted with the others in the one Newton solve (eq. 8 stays
    convex): the solution is the minimiser against perturbations of every coefficient, the offset included,
    and matches the OSQP QP; the same column not named is refused as unexcited."""
    d = make_synthetic(1000, seed=5)
    names = ("k_tau", "k_v", "offset")
    a = Regressors(names, np.column_stack([d.tau, d.dq, np.ones_like(d.tau)]))
    y = d.dq_err + 3e-4
    fit = fit_asymmetric(a, y, 5.0, constant=("offset",))
    best = asymmetric_cost(a.matrix @ fit.x - y, y, 5.0)
    for dx in np.random.default_rng(5).standard_normal((20, 3)):
        x = fit.x * (1.0 + 1e-4 * dx)
        assert asymmetric_cost(a.matrix @ x - y, y, 5.0) > best
    qp = fit_asymmetric(a, y, 5.0, constant=("offset",), solver="osqp")
    np.testing.assert_allclose(qp.x, fit.x, rtol=1e-5)
    with pytest.raises(IdentificationError, match="column 'offset' is constant"):
        fit_asymmetric(a, y, 5.0)


def test_asymmetric_overestimates_less_than_least_squares():
    """With a dead zone, the asymmetric fit over-estimates |dq_err| less often than least squares."""
    d = make_synthetic(3000, seed=3)
    held = make_synthetic(3000, seed=4)
    a = linear_regressors(d.tau, d.dq)
    ls = fit_least_squares(a, d.dq_err)
    asym = fit_asymmetric(a, d.dq_err, 20.0)
    assert asym.overestimation_rate < 0.5 * ls.overestimation_rate
    held_a = linear_regressors(held.tau, held.dq)
    assert overestimation_rate(asym.predict(held_a), held.dq_err) < overestimation_rate(ls.predict(held_a), held.dq_err)


def test_zero_error_samples_count_as_overestimated():
    """Samples with dq_err == 0 weigh w on both sides: they pull the fit like w times as many samples."""
    rng = np.random.default_rng(5)
    tau = rng.uniform(-10, 10, 100)
    dq_err = 1e-3 * np.sign(tau) + 1e-4 * tau
    dq_err[:50] = 0.0
    a = linear_regressors(tau, rng.uniform(-1, 1, 100))
    newton = fit_asymmetric(a, dq_err, 4.0)
    qp = fit_asymmetric(a, dq_err, 4.0, solver="osqp")
    np.testing.assert_allclose(qp.x, newton.x, rtol=1e-6)


@pytest.mark.parametrize("w", [1.0, 0.5, -3.0, float("nan"), float("inf")])
def test_weight_must_exceed_one(w):
    """w <= 1 (or not finite) raises an IdentificationError naming w."""
    a = linear_regressors(np.linspace(-1, 1, 50), np.linspace(1, -1, 50) ** 3)
    with pytest.raises(IdentificationError, match=r"w = .*expected a finite number > 1"):
        fit_asymmetric(a, np.linspace(0, 1, 50), w)


def test_osqp_failure_raises():
    """OSQP stopping short (iteration limit) raises an IdentificationError with its status."""
    d = make_synthetic(500, seed=6)
    with pytest.raises(IdentificationError, match="OSQP status 'maximum iterations reached'"):
        fit_asymmetric(linear_regressors(d.tau, d.dq), d.dq_err, 10.0, solver="osqp", max_iter=5)


def test_unknown_solver_refused():
    """An unknown solver name raises, listing the known ones."""
    d = make_synthetic(100)
    with pytest.raises(IdentificationError, match=r"solver = 'cvx': expected one of \['newton', 'osqp'\]"):
        fit_asymmetric(linear_regressors(d.tau, d.dq), d.dq_err, 10.0, solver="cvx")
