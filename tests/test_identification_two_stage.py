"""Tests of servotau.identification.two_stage (paper section 3.3.1)."""

import numpy as np
import pytest

from servotau.errors import IdentificationError
from servotau.identification import Loss, fit_two_stage, make_synthetic


def exact_data(m=600, seed=0, k_c=0.0):
    d = make_synthetic(m, seed=seed, k_tau=1.2e-4, k_v=0.007, k_c=k_c, e_deadzone=0.0, noise=0.0)
    return d.tau, d.dq, d.dq_err


@pytest.mark.parametrize("loss", [Loss.least_squares(), Loss.asymmetric(10.0)])
def test_recovers_exact_linear_model(loss):
    """Noise-free data (static samples at dq = 0) give k_tau, k_v, k_c back to 1e-9 with either loss."""
    tau, dq, dq_err = exact_data(k_c=4e-4)
    fit = fit_two_stage(tau, dq, dq_err, coulomb=True, static_loss=loss, moving_loss=loss)
    assert fit.coefficients == pytest.approx({"k_tau": 1.2e-4, "k_v": 0.007, "k_c": 4e-4}, rel=1e-9)
    assert fit.static.n_samples + fit.moving.n_samples == fit.n_samples
    assert fit.rms < 1e-15
    np.testing.assert_allclose(fit.predict(tau, dq), dq_err, atol=1e-15)


def test_stages_use_their_samples():
    """Stage 1 fits only k_tau on |dq| < dq_static; stage 2 only k_v on |dq| >= dq_moving."""
    tau, dq, dq_err = exact_data(seed=1)
    fit = fit_two_stage(tau, dq, dq_err, dq_static=0.01, dq_moving=0.5)
    assert fit.static.names == ("k_tau",) and fit.moving.names == ("k_v",)
    assert fit.static.n_samples == np.count_nonzero(np.abs(dq) < 0.01)
    assert fit.moving.n_samples == np.count_nonzero(np.abs(dq) >= 0.5)


def test_asymmetric_stage_judges_overestimation_on_dq_err():
    """Stage 2's metrics are those of the whole model (k_tau tau included) against dq_err."""
    d = make_synthetic(2000, seed=2)
    fit = fit_two_stage(d.tau, d.dq, d.dq_err, moving_loss=Loss.asymmetric(20.0))
    moving = np.abs(d.dq) >= fit.dq_moving
    model = fit.predict(d.tau[moving], d.dq[moving])
    excess = np.sign(d.dq_err[moving]) * (model - d.dq_err[moving])
    assert fit.moving.overestimation_rate == pytest.approx(np.mean(excess > 0))


def test_missing_static_or_moving_samples_raise():
    """No static samples, or a velocity that never reaches dq_moving, raise naming the stage."""
    tau, dq, dq_err = exact_data(seed=3)
    moving = dq != 0
    with pytest.raises(IdentificationError, match=r"stage 1 \(static, \|dq\| < 0.01 rad/s\).*0 samples"):
        fit_two_stage(tau[moving], dq[moving], dq_err[moving])
    with pytest.raises(IdentificationError, match=r"stage 2 \(moving"):
        fit_two_stage(tau, dq, dq_err, dq_moving=10.0)
    with pytest.raises(IdentificationError, match=r"dq_static = -1.0: expected a finite number > 0"):
        fit_two_stage(tau, dq, dq_err, dq_static=-1.0)
