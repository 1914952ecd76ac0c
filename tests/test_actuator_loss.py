"""Tests of servotau.actuator.loss."""

import pytest

from servotau.actuator import Loss
from servotau.errors import IdentificationError


def test_loss_validation():
    """An asymmetric loss needs w > 1, least squares takes no w, unknown kinds are refused."""
    assert Loss.asymmetric(3).w == 3.0 and Loss().kind == "least_squares"
    assert str(Loss.asymmetric(10.0)) == "asymmetric(w=10)"
    for w in (1.0, 0.0, None, float("nan"), True):
        with pytest.raises(IdentificationError, match=r"w = .*: expected a finite number > 1"):
            Loss.asymmetric(w)
    with pytest.raises(IdentificationError, match=r"w = 1e\+300: expected at most 1e\+06"):
        Loss.asymmetric(1e300)  # the weighted normal equations would be singular
    assert Loss.asymmetric(1e6).w == 1e6
    with pytest.raises(IdentificationError, match=r"w = 2.0: expected None"):
        Loss("least_squares", 2.0)
    with pytest.raises(IdentificationError, match=r"loss kind = 'l1': expected one of"):
        Loss("l1")
