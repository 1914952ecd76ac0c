"""identification/workbench/signals.py: derived signals computed once per dataset and its copies."""

import numpy as np
import pytest

from servotau.actuator.signals import Signals


def test_derived_is_computed_once_for_a_signals_and_its_copies_and_again_for_another_source():
    """A filter of q runs once across with_columns copies (a diagnosis refits many models on one q); a copy
    with another q gets its own result; results are read-only."""
    calls = []

    def double(x):
        calls.append(1)
        return 2.0 * x

    s = Signals({"q": np.arange(5.0), "u": np.zeros(5)}, 1e-3, 5)
    a = s.derived("q", ("double",), double)
    copy = s.with_columns(u=np.ones(5))
    assert copy.derived("q", ("double",), double) is a and len(calls) == 1
    other = s.with_columns(q=np.arange(5.0) + 1.0)
    np.testing.assert_array_equal(other.derived("q", ("double",), double), 2.0 * (np.arange(5.0) + 1.0))
    assert len(calls) == 2
    with pytest.raises(ValueError):
        a[0] = 1.0
