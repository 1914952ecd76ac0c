"""Tests of servotau.identification.metrics: the over-estimation rate and the residual RMS."""

import numpy as np
import pytest

from servotau.errors import IdentificationError
from servotau.identification import overestimation_rate, residual_rms, signed_excess


def test_overestimation_definition():
    """Over-estimation is sign(dq_err) (model - dq_err) > 0, and any nonzero model where dq_err == 0."""
    dq_err = np.array([1.0, 1.0, 1.0, -1.0, -1.0, 0.0, 0.0])
    model = np.array([2.0, 0.5, -3.0, -2.0, 0.5, 0.0, -0.1])
    np.testing.assert_array_equal(signed_excess(model, dq_err) > 0, [1, 0, 0, 1, 0, 0, 1])
    assert overestimation_rate(model, dq_err) == pytest.approx(3 / 7)


def test_rms_and_bad_input():
    """RMS is that of model - dq_err; mismatched lengths raise."""
    assert residual_rms(np.array([1.0, -1.0]), np.zeros(2)) == 1.0
    with pytest.raises(IdentificationError, match="mismatched lengths"):
        overestimation_rate(np.zeros(3), np.zeros(4))
