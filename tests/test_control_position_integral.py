"""Tests of servotau.control.position_integral: the conditional, clamped, task-projected position integral."""

import numpy as np
import pytest

from servotau.control.position_integral import PositionIntegral
from servotau.errors import ControlError

PERIOD = 1e-3  # [s]


def _integral(n=3, k_iq=2.0, limit=1e-3, rest_velocity=1e-3):
    k_s = np.array([100.0, 200.0, 300.0][:n])
    return PositionIntegral(k_s, np.full(n, k_iq), np.full(n, limit), rest_velocity, PERIOD)


def test_integrates_the_error_only_while_the_reference_rests_and_clamps():
    """i_q grows by k_iq e_q dt on joints whose |dq_d| < rest_velocity, stays where the reference moves, stops at
    the limit; tau = K_s i_q without a task; reset empties it."""
    pi = _integral()
    e_q = np.array([2e-4, -2e-4, 2e-4])  # [rad]
    dq_d = np.array([0.0, 5e-4, 0.1])  # [rad/s] the third joint moves
    for _ in range(100):
        pi.update(e_q, dq_d)
    np.testing.assert_allclose(pi.i_q, [2.0 * 2e-4 * 0.1, -2.0 * 2e-4 * 0.1, 0.0], rtol=1e-12)
    np.testing.assert_allclose(pi.tau, pi.k_s * pi.i_q, rtol=1e-12)
    for _ in range(5000):  # 5 s: 2 mrad unclamped
        pi.update(e_q, dq_d)
    np.testing.assert_allclose(pi.i_q, [1e-3, -1e-3, 0.0])
    pi.reset()
    assert not pi.i_q.any() and not pi.tau.any()


def test_torque_stays_out_of_the_force_task_directions():
    """With a task Jacobian J the torque satisfies J tau = 0 while the integral still acts in J's null space;
    joints without the integral (k_iq = 0) get none."""
    rng = np.random.default_rng(0)
    n = 6
    k_iq = np.array([2.0, 2.0, 2.0, 2.0, 2.0, 0.0])
    pi = PositionIntegral(np.full(n, 100.0), k_iq, np.full(n, 1.0), 1e-3, PERIOD)
    jac = np.zeros((2, n))
    jac[:, :5] = rng.normal(size=(2, 5))
    e_q = rng.normal(0, 1e-3, n)
    for _ in range(50):
        pi.update(e_q, np.zeros(n), jac)
    np.testing.assert_allclose(jac @ pi.tau, 0.0, atol=1e-12)
    assert pi.tau[5] == 0.0 and np.abs(pi.tau[:5]).max() > 0
    # an error along the task's directions only is not integrated
    pi.reset()
    for _ in range(50):
        pi.update(jac[0].copy(), np.zeros(n), jac)
    np.testing.assert_allclose(pi.i_q, 0.0, atol=1e-15)


def test_off_when_no_joint_has_a_rate():
    pi = _integral(k_iq=0.0)
    assert not pi.active
    assert not pi.update(np.full(3, 1e-3), np.zeros(3)).any()


@pytest.mark.parametrize("kwargs, field", [
    ({"k_iq": -1.0}, "k_iq"),
    ({"limit": np.nan}, "limit"),
    ({"rest_velocity": 0.0}, "rest_velocity"),
])
def test_bad_settings_name_the_field(kwargs, field):
    with pytest.raises(ControlError, match=field) as info:
        _integral(**kwargs)
    assert "expected" in str(info.value)
