"""Tests of the integer delay line (estimation/delay_line.py)."""

import numpy as np
import pytest

from servotau.errors import EstimationError
from servotau.estimation.delay_line import DelayLine


@pytest.mark.parametrize("delay", [0, 1, 5])
def test_outputs_the_sample_pushed_delay_calls_ago(delay):
    """push() returns the input of ``delay`` calls before, zeros before that."""
    line = DelayLine(2, delay)
    out = [line.push(np.array([k, -k], dtype=float)).copy() for k in range(1, 12)]
    for k, y in enumerate(out, start=1):
        expected = k - delay if k > delay else 0
        assert np.array_equal(y, [expected, -expected])


def test_rejects_negative_delay():
    """A negative or non-integer delay raises EstimationError."""
    with pytest.raises(EstimationError):
        DelayLine(3, -1)
    with pytest.raises(EstimationError):
        DelayLine(3, 1.5)
