"""Gain equivalence of the paper's section 4.2: torque-control gains <-> gains seen by the position servo.

Substituting the torque feedback (eq. 11, ``K_i = 0``) and the inverse dynamics (eq. 12) into the
feedforward (eq. 10), with ``tau_hat = M_j ddq_hat + h - J^T f_hat``, the command splits into
feedforward terms and four feedback terms (eq. 13-14)::

    dq_err = K_tau (M_j ddq_d + h - J^T f_d) + K_v dq_hat + K6 e_q + K7 de_q + K8 dde_q + K9 e_f

    K6 = K_tau (I + K_p) K_s                   [-]          position feedback
    K7 = K_tau (I + K_p) K_d                   [s]          velocity feedback
    K8 = K_tau K_p M_j                         [s^2]        acceleration feedback (n x n)
    K9 = -K_tau (K_p J^T (I + K_f) + J^T K_f)  [rad/N, ...] force feedback (n x k)

``K6 = 1`` is the native position servo's stiffness (``dq_err = e_q``), so a user states the position
gain as a fraction of the servo: ``K6 = 1`` gives ``K_s = 1 / (K_tau (1 + K_p))`` (knee of HRP-2:
``k_tau = 5.1e-5``, ``k_p = 2``: about 6536 N m/rad). ``K_tau``, ``K_p``, ``K_s``, ``K_d`` are diagonal and
given here as vectors (n,); ``K_f`` is diagonal over the k force axes, given as a vector (k,). ``J`` is the
(k, n) Jacobian of the force axes with respect to the joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from servotau.errors import ControlError


@dataclass(frozen=True)
class TorqueGains:
    """User gains of the torque controller: vectors (n,) per joint, ``k_f`` (k,) per force axis."""

    k_p: np.ndarray  # [-] torque proportional gain
    k_s: np.ndarray  # [N m/rad] stiffness
    k_d: np.ndarray  # [N m s/rad] damping
    k_f: np.ndarray  # [-] force gain, one per force axis (may be empty)


@dataclass(frozen=True)
class NativeGains:
    """The same gains as seen by the position servo (paper eq. 14)."""

    k6: np.ndarray  # (n,) [-] position feedback, 1 = the native servo
    k7: np.ndarray  # (n,) [s] velocity feedback
    k8: np.ndarray  # (n, n) [s^2] acceleration feedback
    k9: np.ndarray  # (n, k) [rad/N or rad/(N m)] force feedback


def _vector(name: str, value, n: int | None = None, *, positive: bool = False) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1 or (n is not None and arr.shape != (n,)):
        raise ControlError(f"{name} has shape {arr.shape}: expected ({n if n is not None else 'n'},)")
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0 if positive else arr < 0):
        expected = "finite numbers > 0" if positive else "finite numbers >= 0"
        raise ControlError(f"{name} = {arr.tolist()}: expected {expected}")
    return arr


def _matrix(name: str, value, shape: tuple[int, int]) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != shape or not np.all(np.isfinite(arr)):
        raise ControlError(f"{name} has shape {arr.shape}: expected finite numbers of shape {shape}")
    return arr


def k6_from_ks(k_tau, k_p, k_s) -> np.ndarray:
    """``K6 = K_tau (1 + K_p) K_s`` [-] from the stiffness ``k_s`` [N m/rad]."""
    k_tau = _vector("k_tau", k_tau, positive=True)
    return k_tau * (1.0 + _vector("k_p", k_p, k_tau.size)) * _vector("k_s", k_s, k_tau.size)


def ks_from_k6(k_tau, k_p, k6) -> np.ndarray:
    """Stiffness ``K_s = K6 / (K_tau (1 + K_p))`` [N m/rad]; ``K6 = 1`` is the native servo."""
    k_tau = _vector("k_tau", k_tau, positive=True)
    return _vector("k6", k6, k_tau.size) / (k_tau * (1.0 + _vector("k_p", k_p, k_tau.size)))


def k7_from_kd(k_tau, k_p, k_d) -> np.ndarray:
    """``K7 = K_tau (1 + K_p) K_d`` [s] from the damping ``k_d`` [N m s/rad]."""
    k_tau = _vector("k_tau", k_tau, positive=True)
    return k_tau * (1.0 + _vector("k_p", k_p, k_tau.size)) * _vector("k_d", k_d, k_tau.size)


def kd_from_k7(k_tau, k_p, k7) -> np.ndarray:
    """Damping ``K_d = K7 / (K_tau (1 + K_p))`` [N m s/rad]."""
    k_tau = _vector("k_tau", k_tau, positive=True)
    return _vector("k7", k7, k_tau.size) / (k_tau * (1.0 + _vector("k_p", k_p, k_tau.size)))


def k8_from_kp(k_tau, k_p, mass_matrix) -> np.ndarray:
    """``K8 = K_tau K_p M_j`` [s^2] (n, n) for the joint-space mass matrix ``M_j`` [kg m^2]."""
    k_tau = _vector("k_tau", k_tau, positive=True)
    n = k_tau.size
    return (k_tau * _vector("k_p", k_p, n))[:, None] * _matrix("mass_matrix", mass_matrix, (n, n))


def kp_from_k8(k_tau, k8, mass_matrix) -> np.ndarray:
    """Diagonal ``K_p`` whose ``K_tau K_p M_j`` is closest to ``k8`` (row by row least squares; exact if ``k8``
    came from :func:`k8_from_kp`)."""
    k_tau = _vector("k_tau", k_tau, positive=True)
    n = k_tau.size
    m = _matrix("mass_matrix", mass_matrix, (n, n))
    rows = _matrix("k8", k8, (n, n)) / k_tau[:, None]  # = K_p M_j
    return np.einsum("ij,ij->i", rows, m) / np.einsum("ij,ij->i", m, m)


def k9_from_kf(k_tau, k_p, jacobian, k_f) -> np.ndarray:
    """``K9 = -K_tau (K_p J^T (I + K_f) + J^T K_f)`` (n, k) for the (k, n) force-axis Jacobian ``J``."""
    k_tau = _vector("k_tau", k_tau, positive=True)
    n = k_tau.size
    k_p = _vector("k_p", k_p, n)
    jac = np.asarray(jacobian, dtype=float)
    if jac.ndim != 2 or jac.shape[1] != n:
        raise ControlError(f"jacobian has shape {jac.shape}: expected (k, {n})")
    k_f = _vector("k_f", k_f, jac.shape[0])
    jt = jac.T
    return -k_tau[:, None] * (k_p[:, None] * jt * (1.0 + k_f)[None, :] + jt * k_f[None, :])


def kf_from_k9(k_tau, k_p, jacobian, k9) -> np.ndarray:
    """Diagonal ``K_f`` (k,) whose :func:`k9_from_kf` is closest to ``k9`` (column by column least squares).

    Column j of K9 is ``-K_tau (K_p + k_f,j (I + K_p)) J^T[:, j]``, linear in ``k_f,j``.
    """
    k_tau = _vector("k_tau", k_tau, positive=True)
    n = k_tau.size
    k_p = _vector("k_p", k_p, n)
    jac = np.asarray(jacobian, dtype=float)
    if jac.ndim != 2 or jac.shape[1] != n:
        raise ControlError(f"jacobian has shape {jac.shape}: expected (k, {n})")
    k9 = _matrix("k9", k9, (n, jac.shape[0]))
    jt = jac.T
    base = -(k_tau * k_p)[:, None] * jt  # K9 at k_f = 0
    slope = -(k_tau * (1.0 + k_p))[:, None] * jt  # d K9 / d k_f,j, column j
    norm = np.einsum("ij,ij->j", slope, slope)
    if np.any(norm == 0.0):
        raise ControlError(f"jacobian column(s) {np.flatnonzero(norm == 0.0).tolist()} of J^T are zero: "
                           "expected every force axis to move at least one joint")
    return np.einsum("ij,ij->j", slope, k9 - base) / norm


def native_from_torque(k_tau, gains: TorqueGains, mass_matrix, jacobian=None) -> NativeGains:
    """The gains K6..K9 of the paper's eq. 14 from the torque-control gains (K_p, K_s, K_d, K_f)."""
    k_tau = _vector("k_tau", k_tau, positive=True)
    jac = np.zeros((0, k_tau.size)) if jacobian is None else jacobian
    return NativeGains(
        k6=k6_from_ks(k_tau, gains.k_p, gains.k_s),
        k7=k7_from_kd(k_tau, gains.k_p, gains.k_d),
        k8=k8_from_kp(k_tau, gains.k_p, mass_matrix),
        k9=k9_from_kf(k_tau, gains.k_p, jac, gains.k_f),
    )


def torque_from_native(k_tau, native: NativeGains, mass_matrix, jacobian=None) -> TorqueGains:
    """The torque-control gains (K_p, K_s, K_d, K_f) from K6..K9 (inverse of :func:`native_from_torque`)."""
    k_tau = _vector("k_tau", k_tau, positive=True)
    k_p = kp_from_k8(k_tau, native.k8, mass_matrix)
    if np.any(k_p < -1e-12):
        raise ControlError(f"k8 gives k_p = {k_p.tolist()}: expected k_p >= 0")
    k_p = np.maximum(k_p, 0.0)
    jac = np.zeros((0, k_tau.size)) if jacobian is None else jacobian
    k_f = kf_from_k9(k_tau, k_p, jac, native.k9) if np.asarray(jac).shape[0] else np.zeros(0)
    return TorqueGains(
        k_p=k_p,
        k_s=ks_from_k6(k_tau, k_p, native.k6),
        k_d=kd_from_k7(k_tau, k_p, native.k7),
        k_f=k_f,
    )
