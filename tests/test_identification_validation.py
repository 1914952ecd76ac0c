"""Bad data refused by every fit (servotau.identification.validation), with the field named."""

import math

import numpy as np
import pytest

from servotau.errors import IdentificationError
from servotau.identification import Loss, fit_linear_model, fit_two_stage, make_synthetic

FITS = {
    "least_squares": lambda tau, dq, e: fit_linear_model(tau, dq, e),
    "asymmetric": lambda tau, dq, e: fit_linear_model(tau, dq, e, loss=Loss.asymmetric(10.0)),
    "osqp": lambda tau, dq, e: fit_linear_model(tau, dq, e, loss=Loss.asymmetric(10.0), solver="osqp"),
    "two_stage": lambda tau, dq, e: fit_two_stage(tau, dq, e),
}


@pytest.fixture
def data():
    d = make_synthetic(200, seed=0)
    return d.tau.copy(), d.dq.copy(), d.dq_err.copy()


@pytest.mark.parametrize("fit", FITS.values(), ids=FITS.keys())
@pytest.mark.parametrize("field", ["tau", "dq", "dq_err"])
@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_input_names_field(data, fit, field, bad):
    """A NaN or inf sample raises an IdentificationError naming the input and the index."""
    arrays = dict(zip(("tau", "dq", "dq_err"), data, strict=True))
    arrays[field][17] = bad
    with pytest.raises(IdentificationError, match=rf"{field}: 1 of 200 samples are NaN or inf \(first at index 17"):
        fit(*arrays.values())


@pytest.mark.parametrize("fit", FITS.values(), ids=FITS.keys())
def test_mismatched_lengths(data, fit):
    """Arrays of different lengths raise, listing every length."""
    tau, dq, dq_err = data
    with pytest.raises(IdentificationError, match=r"mismatched lengths \(.*dq_err: 199"):
        fit(tau, dq, dq_err[:-1])


@pytest.mark.parametrize("fit", FITS.values(), ids=FITS.keys())
def test_too_few_samples(data, fit):
    """Fewer samples than the minimum raise, stating the minimum."""
    tau, dq, dq_err = (a[:8] for a in data)
    with pytest.raises(IdentificationError, match=r"8 samples: expected at least|samples: expected at least 10"):
        fit(tau, dq, dq_err)


@pytest.mark.parametrize("fit", [FITS["least_squares"], FITS["asymmetric"]], ids=["least_squares", "asymmetric"])
def test_no_motion(data, fit):
    """An all-zero velocity (no excitation of k_v) raises naming the column."""
    tau, dq, dq_err = data
    with pytest.raises(IdentificationError, match=r"column 'k_v' is all zero: no excitation"):
        fit(tau, np.zeros_like(dq), dq_err)


def test_constant_torque(data):
    """A constant torque (k_tau not excited) raises naming the column."""
    tau, dq, dq_err = data
    with pytest.raises(IdentificationError, match=r"column 'k_tau' is constant \(= 5\): no excitation"):
        fit_linear_model(np.full_like(tau, 5.0), dq, dq_err)


def test_one_direction_refuses_coulomb(data):
    """Motion in one direction only makes sign(dq) constant: the Coulomb column is refused."""
    tau, dq, dq_err = data
    with pytest.raises(IdentificationError, match=r"column 'k_c' is constant"):
        fit_linear_model(tau, np.abs(dq) + 0.1, dq_err, coulomb=True)


def test_not_an_array():
    """A 2-D or non-numeric input raises naming it."""
    with pytest.raises(IdentificationError, match=r"tau: expected a 1-D array of samples, got shape \(2, 3\)"):
        fit_linear_model(np.zeros((2, 3)), np.zeros(6), np.zeros(6))
    with pytest.raises(IdentificationError, match=r"dq: expected a 1-D array of floats"):
        fit_linear_model(np.zeros(3), ["a", "b", "c"], np.zeros(3))
