"""Tests of servotau.control.trajectory: the force-compatible posture reference (paper 5.4)."""

import numpy as np
import pytest

from servotau.control.trajectory import ForceCompatiblePosture
from servotau.errors import ControlError

JOINTS = np.arange(2, 8)


def _jacobian(rng):
    j = np.zeros((3, 12))
    j[:, JOINTS] = rng.normal(0, 0.3, (3, 6))
    return j


def test_reference_moves_the_contact_by_the_calibrated_compliance_times_the_force_change():
    """During calibration the reference follows the measured displacement; after it (and the fade of the step),
    J (q_ref - q0) = C (f_d - f0) with C of the data (drift and other axes ignored)."""
    rng = np.random.default_rng(0)
    jac, q0 = _jacobian(rng), rng.normal(0, 0.5, 12)
    c_z = np.array([1e-5, -2e-5, 4e-5])  # [m/N] displacement per N of f_z
    f0 = np.array([2.0, -1.0, 250.0])
    pinv = np.linalg.pinv(jac[:, JOINTS])
    posture = ForceCompatiblePosture(q0, JOINTS, calibration=2.0)
    dt = 1e-3
    x_before = np.zeros(3)
    for k in range(2001):
        t = k * dt
        f_d = np.array([0.0, 0.0, f0[2] + 40 * np.sin(np.pi * t)])
        f_hat = f0 + (f_d - f0) * 0.6 + np.array([0.5 * np.sin(np.pi * t), 0.3, 0.0])  # x, y follow z
        x = c_z * (f_hat[2] - f0[2]) + 1e-4 * t  # plus a slow drift, not compliance
        q_hat = q0.copy()
        q_hat[JOINTS] += pinv @ x
        ref = posture.update(t, q_hat, jac, f_hat, f_d)
        if posture.compliance is None and k > 0:  # calibration: the measured displacement
            np.testing.assert_allclose(jac @ (ref.q - q0), x, rtol=0, atol=1e-12)
        if k == 2000:  # the fit: the reference continues from the measured displacement, then fades to C (f_d - f0)
            np.testing.assert_allclose(jac @ (ref.q - q0), x_before, rtol=0, atol=1e-12)
        x_before = x
    np.testing.assert_allclose(posture.compliance[:, 2], c_z, rtol=1e-6)
    assert not posture.compliance[:, :2].any()  # axes whose reference does not vary are not regressors
    f_d = np.array([0.0, 0.0, f0[2] + 30.0])
    ref = posture.update(2.5, q0, jac, f0, f_d)
    np.testing.assert_allclose(jac @ (ref.q - q0), c_z * 30.0, rtol=1e-9, atol=1e-15)
    others = np.setdiff1d(np.arange(12), JOINTS)
    np.testing.assert_array_equal(ref.q[others], q0[others])
    ref = posture.update(2.6, q0, jac, f0, np.array([0.0, 0.0, f0[2] + 1e4]))  # 40 cm: clipped to x_max
    np.testing.assert_allclose(np.abs(jac @ (ref.q - q0)), 0.01, rtol=1e-9)


def test_reference_velocity_and_acceleration_follow_the_force_reference():
    """After calibration, J dq_ref = C df_d/dt and J ddq_ref = C d2f_d/dt2 (finite differences of the smooth force
    reference), so the velocity feedback does not brake the motion the force task needs; 0 before and when clipped."""
    rng = np.random.default_rng(1)
    jac, q0 = _jacobian(rng), rng.normal(0, 0.5, 12)
    c_z = np.array([1e-5, -2e-5, 4e-5])  # [m/N]
    f0 = np.array([0.0, 0.0, 250.0])
    pinv = np.linalg.pinv(jac[:, JOINTS])
    posture = ForceCompatiblePosture(q0, JOINTS, calibration=1.0)
    dt, w, a = 1e-3, np.pi, 40.0
    for k in range(1501):
        t = k * dt
        f_d = np.array([0.0, 0.0, f0[2] + a * np.sin(w * t)])
        q_hat = q0.copy()
        q_hat[JOINTS] += pinv @ (c_z * (f_d[2] - f0[2]))
        ref = posture.update(t, q_hat, jac, f_d, f_d)
        if posture.compliance is None or k < 1002:  # calibrating, then one tick without a previous velocity
            assert not ref.ddq.any()
            continue
        # backward differences: the velocity of half a tick ago, the acceleration of one tick ago
        np.testing.assert_allclose(jac @ ref.dq, c_z * a * w * np.cos(w * (t - dt / 2)), rtol=0,
                                   atol=1e-6 * a * w * 4e-5)
        np.testing.assert_allclose(jac @ ref.ddq, -c_z * a * w**2 * np.sin(w * (t - dt)), rtol=0,
                                   atol=1e-4 * a * w**2 * 4e-5)
    ref = posture.update(1.6, q0, jac, f0, np.array([0.0, 0.0, f0[2] + 1e4]))  # clipped: holds still
    assert not ref.dq[JOINTS].any()


def test_compliance_is_refitted_every_calibration_period():
    """With ``refit``, C is refitted on each period's samples (the support's compliance grows with the amplitude) and
    kept through a period where the force reference holds still; without it, the first period's C stays."""
    rng = np.random.default_rng(2)
    jac, q0 = _jacobian(rng), rng.normal(0, 0.5, 12)
    pinv = np.linalg.pinv(jac[:, JOINTS])
    f0 = np.array([0.0, 0.0, 250.0])
    c_z = {0: np.array([1e-5, -2e-5, 4e-5]), 1: np.array([1.5e-5, -3e-5, 6e-5])}  # [m/N] first, second period
    postures = {refit: ForceCompatiblePosture(q0, JOINTS, calibration=1.0, refit=refit) for refit in (True, False)}
    for k in range(3001):
        t = k * 1e-3
        f_d = np.array([0.0, 0.0, f0[2] + 40 * np.sin(2 * np.pi * min(t, 2.0))])  # holds still after 2 s
        q_hat = q0.copy()
        q_hat[JOINTS] += pinv @ (c_z[min(int(t), 1)] * (f_d[2] - f0[2]))
        for posture in postures.values():
            posture.update(t, q_hat, jac, f_d, f_d)
    assert postures[True].fits == 3 and postures[False].fits == 1
    np.testing.assert_allclose(postures[True].compliance[:, 2], c_z[1], rtol=1e-3)
    np.testing.assert_allclose(postures[False].compliance[:, 2], c_z[0], rtol=1e-3)


def test_bad_settings_raise():
    """A calibration time or a displacement bound that is not > 0, or a fade that is not >= 0, raises ControlError
    naming it."""
    with pytest.raises(ControlError, match="calibration"):
        ForceCompatiblePosture(np.zeros(12), JOINTS, calibration=0.0)
    with pytest.raises(ControlError, match="max_displacement"):
        ForceCompatiblePosture(np.zeros(12), JOINTS, calibration=1.0, max_displacement=-1.0)
    with pytest.raises(ControlError, match="fade"):
        ForceCompatiblePosture(np.zeros(12), JOINTS, calibration=1.0, fade=float("nan"))
