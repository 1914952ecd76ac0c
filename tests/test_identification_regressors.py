"""Tests of servotau.identification.regressors."""

import math

import numpy as np
import pytest

from servotau.errors import IdentificationError
from servotau.identification import Regressors, linear_regressors, sign


def test_columns_named_and_ordered():
    """linear_regressors gives columns k_tau, k_v, k_c (sign, zero at zero), then extras, read-only."""
    a = linear_regressors([1.0, -2.0, 3.0], [0.5, 0.0, -0.5], coulomb=True, extra={"cog": [1.0, 2.0, 3.0]})
    assert a.names == ("k_tau", "k_v", "k_c", "cog") and a.n_samples == 3
    np.testing.assert_array_equal(a.column("k_c"), [1.0, 0.0, -1.0])
    np.testing.assert_array_equal(sign(np.array([-2.0, 0.0, 3.0])), [-1.0, 0.0, 1.0])
    assert not a.matrix.flags.writeable
    assert a.select(np.array([True, False, True])).n_samples == 2


def test_bad_regressors_refused():
    """Duplicate names, wrong shape, NaN in a column or a clashing extra name raise naming it."""
    with pytest.raises(IdentificationError, match="expected distinct non-empty strings"):
        Regressors(("a", "a"), np.zeros((3, 2)))
    with pytest.raises(IdentificationError, match=r"shape \(3, 3\): expected \(n_samples, 2\)"):
        Regressors(("a", "b"), np.zeros((3, 3)))
    with pytest.raises(IdentificationError, match=r"column 'b': 1 samples are NaN or inf \(first at index 2\)"):
        Regressors(("a", "b"), np.array([[0, 0], [0, 0], [0, math.nan]]))
    with pytest.raises(IdentificationError, match=r"extra regressor 'k_v': expected a name other than"):
        linear_regressors([1.0], [1.0], extra={"k_v": [1.0]})
    with pytest.raises(IdentificationError, match=r"mismatched lengths \(tau: 2, dq: 2, cog: 1\)"):
        linear_regressors([1.0, 2.0], [1.0, 2.0], extra={"cog": [1.0]})
