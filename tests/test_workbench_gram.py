"""The diagnosis's fits from normal equations (identification/workbench/gram.py) against the direct fit."""

import numpy as np
import pytest

from servotau.actuator import Loss
from servotau.errors import IdentificationError
from servotau.identification.workbench.gram import Normal, loss_of, near_ties, solve_gram
from servotau.identification.workbench.model import solve


def _data(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(n, 2))
    cols = np.column_stack([np.tanh(base[:, 1] / 0.1), rng.normal(size=n)])
    y = base @ [0.3, -0.2] + cols @ [0.05, 0.01] + 1e-3 * rng.normal(size=n)
    mask = np.ones(n, dtype=bool)
    mask[500:900] = False
    return base, cols, y, mask


def test_normal_equations_give_the_direct_fit_and_loss():
    base, cols, y, mask = _data()
    names = ["k_tau", "k_v", "e#0", "e#1"]
    ne = Normal(base, y, mask)
    g, aty, colsum = ne.system(cols)
    x = solve_gram(names, g, aty, colsum, ne.n)
    a = np.column_stack([base, cols])
    x_direct = solve(names, a, y, Loss.least_squares(), mask)
    np.testing.assert_allclose(x, x_direct, rtol=1e-10)
    r = (y - a @ x)[mask]
    assert loss_of(x, g, aty, ne.yty) == pytest.approx(float(r @ r), rel=1e-6)


def test_a_column_zero_on_the_rows_is_refused_as_by_solve():
    base, cols, y, mask = _data()
    cols = cols.copy()
    cols[:, 0] = 0.0
    cols[600:700, 0] = 1.0  # excited only in the held-out rows
    ne = Normal(base, y, mask)
    names = ["k_tau", "k_v", "e#0", "e#1"]
    with pytest.raises(IdentificationError, match="e#0' is zero or constant") as direct:
        solve(names, np.column_stack([base, cols]), y, Loss.least_squares(), mask)
    with pytest.raises(IdentificationError) as gram:
        solve_gram(names, *ne.system(cols), ne.n)
    assert str(gram.value) == str(direct.value)


def test_near_ties_only_when_the_gram_losses_cannot_order():
    assert near_ties([1.0, 2.0, 3.0], yty=10.0) == []
    assert near_ties([1.0, 1.0 + 1e-12, 3.0], yty=10.0) == [0, 1]
    assert near_ties([1.0, 1.0 + 1e-6, 3.0], yty=1e9) == [0, 1]  # |y|^2 large: the losses lose digits
