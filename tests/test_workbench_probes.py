"""The probes' one-hot families (identification/workbench/probes.py): kept as bin indices and fitted in closed form,
they give the dense ridge fit's coefficients."""

import numpy as np

from servotau.identification.workbench.probes import _bin_ridge, _bins, _ridge


def _onehot(index, k):
    m = np.zeros((len(index), k))
    m[np.arange(len(index)), index] = 1.0
    return m


def test_bins_keep_the_used_columns_of_the_dense_design_in_order():
    rng = np.random.default_rng(0)
    index = rng.choice([0, 3, 4, 9, 11], size=500)  # bins 1, 2, 5..8, 10 never used
    dense = _onehot(index, 12)
    bins = _bins(index, 12)
    assert bins.k == 5
    np.testing.assert_array_equal(bins.columns(), dense[:, np.any(dense != 0, axis=0)])


def test_closed_form_fit_equals_the_dense_ridge_with_bins_empty_in_training():
    rng = np.random.default_rng(1)
    for _ in range(20):
        n, k = int(rng.integers(50, 3000)), int(rng.integers(2, 64))
        bins = _bins(rng.integers(0, k, size=n), k)
        y = rng.normal(size=n) * rng.uniform(1e-4, 1e3) + rng.normal()
        train = rng.random(n) < 0.8
        train[np.isin(bins.index, rng.choice(bins.k, size=max(1, bins.k // 4), replace=False))] = False
        assert 0 < np.count_nonzero(train)
        empty = np.bincount(bins.index[train], minlength=bins.k) == 0
        assert empty.any()
        dense = _ridge(bins.columns()[train], y[train])
        closed = _bin_ridge(bins.index[train], bins.k, y[train])
        np.testing.assert_allclose(closed, dense, rtol=1e-12, atol=1e-15 * np.abs(dense).max())
        np.testing.assert_array_equal(closed[empty], 0.0)
