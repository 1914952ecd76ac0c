"""Tests of servotau.control.gains: the paper's gain equivalence K6..K9 <-> (K_p, K_s, K_d, K_f)."""

import numpy as np
import pytest

from servotau.control.gains import (
    NativeGains,
    TorqueGains,
    k6_from_ks,
    k7_from_kd,
    k8_from_kp,
    k9_from_kf,
    kd_from_k7,
    kf_from_k9,
    kp_from_k8,
    ks_from_k6,
    native_from_torque,
    torque_from_native,
)
from servotau.errors import ControlError

K_TAU_LEG = np.array([2.12e-4, 3.0e-5, 1.2e-4, 5.1e-5, 1.77e-4, 2.4e-4])  # paper's Table 1 [rad/(N m)]


def _random_problem(seed=0, n=6, k=3):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, n))
    mass = a @ a.T + n * np.eye(n)  # SPD
    jac = rng.standard_normal((k, n))
    gains = TorqueGains(k_p=rng.uniform(0.5, 3, n), k_s=rng.uniform(100, 5000, n), k_d=rng.uniform(1, 50, n),
                        k_f=rng.uniform(0.1, 2, k))
    return mass, jac, gains


def test_knee_stiffness_matches_the_authors_number():
    """K6 = 1 with k_p = 2 and the knee's k_tau = 5.1e-5 gives k_s = 1/(k_tau (1 + k_p)), about 6536 N m/rad."""
    k_s = ks_from_k6(5.1e-5, 2.0, 1.0)[0]
    assert k_s == pytest.approx(1.0 / (5.1e-5 * 3.0), rel=1e-12)
    assert round(k_s) == 6536
    assert k6_from_ks(5.1e-5, 2.0, 6535.9477)[0] == pytest.approx(1.0, abs=1e-6)


def test_k6_and_k7_conversions_invert_each_other():
    """ks_from_k6 / k6_from_ks and kd_from_k7 / k7_from_kd are inverse maps, joint by joint."""
    k_p = np.full(6, 2.0)
    k6 = np.array([1.0, 0.5, 0.25, 0.1, 1.0, 0.0])
    np.testing.assert_allclose(k6_from_ks(K_TAU_LEG, k_p, ks_from_k6(K_TAU_LEG, k_p, k6)), k6, rtol=1e-12)
    k_d = np.array([1.0, 20.0, 3.0, 0.0, 7.0, 11.0])
    np.testing.assert_allclose(kd_from_k7(K_TAU_LEG, k_p, k7_from_kd(K_TAU_LEG, k_p, k_d)), k_d, rtol=1e-12)


def test_k8_and_k9_follow_the_paper_matrix_formulas():
    """K8 = K_tau K_p M and K9 = -K_tau (K_p J^T (I + K_f) + J^T K_f), written with explicit diagonal matrices."""
    mass, jac, g = _random_problem()
    kt, kp, kf = np.diag(K_TAU_LEG), np.diag(g.k_p), np.diag(g.k_f)
    np.testing.assert_allclose(k8_from_kp(K_TAU_LEG, g.k_p, mass), kt @ kp @ mass, rtol=1e-12)
    expected = -kt @ (kp @ jac.T @ (np.eye(3) + kf) + jac.T @ kf)
    np.testing.assert_allclose(k9_from_kf(K_TAU_LEG, g.k_p, jac, g.k_f), expected, rtol=1e-12)


def test_native_and_torque_gains_invert_each_other():
    """torque_from_native(native_from_torque(g)) returns g, and the other way round."""
    mass, jac, g = _random_problem(seed=3)
    native = native_from_torque(K_TAU_LEG, g, mass, jac)
    back = torque_from_native(K_TAU_LEG, native, mass, jac)
    for name in ("k_p", "k_s", "k_d", "k_f"):
        np.testing.assert_allclose(getattr(back, name), getattr(g, name), rtol=1e-9, err_msg=name)
    again = native_from_torque(K_TAU_LEG, back, mass, jac)
    for name in ("k6", "k7", "k8", "k9"):
        np.testing.assert_allclose(getattr(again, name), getattr(native, name), rtol=1e-9, err_msg=name)


def test_inverse_helpers_recover_kp_and_kf():
    """kp_from_k8 and kf_from_k9 recover the diagonal gains that built K8 and K9."""
    mass, jac, g = _random_problem(seed=5)
    np.testing.assert_allclose(kp_from_k8(K_TAU_LEG, k8_from_kp(K_TAU_LEG, g.k_p, mass), mass), g.k_p, rtol=1e-10)
    k9 = k9_from_kf(K_TAU_LEG, g.k_p, jac, g.k_f)
    np.testing.assert_allclose(kf_from_k9(K_TAU_LEG, g.k_p, jac, k9), g.k_f, rtol=1e-10)


def test_without_force_task_k9_is_empty():
    """Without a force task (no Jacobian) K9 has zero columns and K_f is empty both ways."""
    mass, _, g = _random_problem()
    g = TorqueGains(g.k_p, g.k_s, g.k_d, np.zeros(0))
    native = native_from_torque(K_TAU_LEG, g, mass)
    assert native.k9.shape == (6, 0)
    assert torque_from_native(K_TAU_LEG, native, mass).k_f.shape == (0,)


@pytest.mark.parametrize("call, field", [
    (lambda: ks_from_k6([-5.1e-5], 2.0, 1.0), "k_tau"),
    (lambda: ks_from_k6([5.1e-5], [np.nan], 1.0), "k_p"),
    (lambda: k6_from_ks([5.1e-5], 2.0, [-1.0]), "k_s"),
    (lambda: k9_from_kf(K_TAU_LEG, np.ones(6), np.ones((2, 5)), np.ones(2)), "jacobian"),
    (lambda: torque_from_native(K_TAU_LEG, NativeGains(np.ones(6), np.ones(6), np.ones((5, 5)), np.zeros((6, 0))),
                                np.eye(6)), "k8"),
])
def test_bad_inputs_name_the_field(call, field):
    """Negative, NaN or mis-shaped gains raise ControlError naming the argument and what was expected."""
    with pytest.raises(ControlError, match=field) as info:
        call()
    assert "expected" in str(info.value)
