"""Tests of servotau.control.terms: the preallocated per-tick outputs."""

import numpy as np
import pytest

from servotau.control.terms import COMPONENTS, SIGNALS, WRENCHES, ControlTerms


def test_arrays_keep_their_identity_and_sum_the_components():
    """Every output is preallocated with the right size; component_sum() adds exactly the COMPONENTS."""
    t = ControlTerms(30)
    assert all(getattr(t, n).shape == (30,) for n in COMPONENTS + SIGNALS)
    assert all(getattr(t, n).shape == (6,) for n in WRENCHES)
    ids = {n: id(a) for n, a in t.components().items()}
    for k, name in enumerate(COMPONENTS):
        getattr(t, name)[:] = 10.0**k
    t.q_des[:] = 1e9  # not a component
    np.testing.assert_allclose(t.component_sum(), sum(10.0**k for k in range(len(COMPONENTS))))
    assert ids == {n: id(a) for n, a in t.components().items()}


def test_as_dict_copies():
    """as_dict() is a snapshot: later ticks do not change it."""
    t = ControlTerms(3)
    t.tau_d[:] = 1.0
    snap = t.as_dict()
    t.tau_d[:] = 2.0
    assert snap["tau_d"].tolist() == [1.0, 1.0, 1.0]
    assert set(COMPONENTS) <= set(snap)


def test_shared_buffers_are_used_as_given():
    """Arrays passed in ``shared`` are the outputs themselves; an unknown name or a wrong shape is refused."""
    buf = np.zeros(4)
    assert ControlTerms(4, {"tau_d": buf}).tau_d is buf
    with pytest.raises(ValueError, match="tau_x"):
        ControlTerms(4, {"tau_x": buf})
    with pytest.raises(ValueError, match="f_d"):
        ControlTerms(4, {"f_d": buf})
