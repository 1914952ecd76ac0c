"""Tests of servotau.actuator.effects.viscous_power: the power-law viscous term and its recovery."""

import numpy as np
from support.synthetic import K_C, synthetic_table

from servotau.actuator import Signals, get_effect
from servotau.identification.workbench import diagnose, load_dataset, parse_spec


def test_the_term_is_an_odd_power_of_the_speed():
    """phi = sgn(dq) |dq|^delta [rad/s = 1 at V_REF]: 0.25^0.5 = 0.5, odd, 0 at rest; the grid leaves out
    delta = 1 (the base model's k_v)."""
    from servotau.actuator.effects.viscous_power import GRID, scalar, viscous_power

    dq = np.array([-0.25, 0.0, 0.25, 4.0])
    s = Signals({"dq": dq}, None, 4)
    np.testing.assert_allclose(viscous_power(s, delta=0.5), [-0.5, 0.0, 0.5, 2.0], rtol=1e-15)
    np.testing.assert_allclose(viscous_power(s, delta=2.0), [-0.0625, 0.0, 0.0625, 16.0], rtol=1e-15)
    assert [scalar({"dq": float(v)}, delta=0.5) for v in dq] == [-0.5, 0.0, 0.5, 2.0]
    assert all(0.0 < g["delta"] < 1.0 for g in GRID)  # sub-linear, never k_v's column


def test_the_scalar_formula_is_the_regressor_on_every_shape():
    rng = np.random.default_rng(0)
    dq = rng.normal(size=200) * 0.3
    e = get_effect("viscous_power")
    s = Signals({"dq": dq}, 1e-3, 200)
    for shape in e.grid:
        np.testing.assert_allclose([e.scalar({"dq": float(v)}, **shape) for v in dq], e.evaluate(s, shape),
                                   rtol=1e-13, atol=0)


def test_hidden_power_law_friction_is_named_first():
    """A friction 0.3 mrad sgn(v) |v / 0.5 rad/s|^0.45 in place of the table's Coulomb friction (as the plant family
    draws it), diagnosed from the paper's model: named before coulomb, at an exponent within 0.1 of the truth
    (its linear part left to k_v)."""
    def friction(t, q, dq, tau):
        return 3e-4 * np.sign(dq) * np.abs(dq / 0.5) ** 0.45 - K_C * np.tanh(dq / 0.005)

    ds = load_dataset(synthetic_table(friction, seconds=8.0))
    d = diagnose(ds, parse_spec("paper", ds.signals))
    assert d.verdict == "missing_effect" and d.top.effect == "viscous_power", d.message
    assert abs(d.top.shape["delta"] - 0.45) <= 0.1 and d.top.heldout_gain > 0.5, (d.top.shape, d.top.heldout_gain)
