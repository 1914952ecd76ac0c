"""The controller's gains checked against the identified motor model before anything moves (issue 22).

:func:`predicted_radii` builds each torque joint's linearised loop (:mod:`.stability`: the identified k_tau, k_v,
the joint's inertia, the estimator's filters, the configured k_p, K6 and K7) and returns its spectral radius;
:func:`check_predicted_stable` refuses a config whose model predicts a loop that diverges faster than
:data:`RHO_MAX` per period, naming the motor file, the joint and the fields. The linear loop leaves out friction
and the dead band, which damp slow oscillations (the nominal servo's joints reach 1.004-1.015 at the shipped gains
and run stable), so the threshold refuses only fast divergence: a model with a far too small ``k_tau`` (a servo
stiffer than the period can hold), a ``k_v`` whose feedforward outruns the velocity feedback, a ``k_p`` that
makes the torque loop ring.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from servotau.errors import ConfigError

from .stability import LoopModel, radius

RHO_MAX = 1.02  # [-] per period: growth by e in 50 periods; the shipped gains reach at most ~1.015


def joint_inertias(info, joints) -> dict[str, float]:
    """Diagonal of the fixed-base joint-space mass matrix [kg m^2] (with the rotors' armature when the model has
    it) at the model's neutral posture, per joint of ``joints``."""
    from .dynamics import RobotDynamics

    dyn = RobotDynamics(info.model_path, info.joint_names, "fixed", info.root_joint)
    n = len(info.joint_names)
    dyn.set_state(np.zeros(n), np.zeros(n))
    m = dyn.mass_matrix()
    return {j: float(m[info.joint_names.index(j), info.joint_names.index(j)]) for j in joints}


def predicted_radii(config, info, estimator=None) -> dict[str, float]:
    """Spectral radius of each torque joint's linearised loop at the config's gains (:mod:`.stability`)."""
    from .gains import k6_from_ks, k7_from_kd

    window, order = _encoder_filter(estimator)
    inertia = joint_inertias(info, config.torque_joints)
    out = {}
    for j, g in config.gains.items():
        m = config.motors[j]
        k6 = float(k6_from_ks(m.k_tau, g.k_p, g.k_s)[0])
        k7 = float(k7_from_kd(m.k_tau, g.k_p, g.k_d)[0])
        loop = LoopModel(m.k_tau, m.k_v, inertia[j], info.period, window, order)
        out[j] = radius(loop, k6, k7, g.k_p)
    return out


def check_predicted_stable(config, info, motors_file: str, estimator=None) -> Mapping[str, float]:
    """:func:`predicted_radii`, or a :class:`ConfigError` naming ``motors_file``, the joint, its k_tau and k_v
    and the gains when one exceeds :data:`RHO_MAX`."""
    radii = predicted_radii(config, info, estimator)
    for j, rho in radii.items():
        if not (np.isfinite(rho) and rho <= RHO_MAX):
            m, g = config.motors[j], config.gains[j]
            raise ConfigError(
                f"{motors_file}: joint \"{j}\": fields 'joints.{j}.k_tau' = {m.k_tau:.4g}, 'joints.{j}.k_v' = "
                f"{m.k_v:.4g} with k_p = {g.k_p:g}, k_s = {g.k_s:.4g} N m/rad, k_d = {g.k_d:.4g} N m s/rad: the model "
                f"predicts an unstable torque loop (spectral radius {rho:.4f} per period): expected at most "
                f"{RHO_MAX} (a servo model the controller can hold: k_tau, k_v as identified by servotau identify)")
    return radii


def _encoder_filter(estimator) -> tuple[int, int]:
    """(window, order) of the estimator's encoder filter (default: the control loop's variant)."""
    if estimator is None:
        from .loop import estimator_config

        estimator = estimator_config()
    enc = estimator.encoders
    return int(enc.window), int(enc.order)
