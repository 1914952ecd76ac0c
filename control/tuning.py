"""The controller's gains checked against the identified motor model before anything moves (issue 22).

:func:`loop_models` builds each torque joint's linearised loop (:mod:`.stability`: the identified k_tau, k_v, the
joint's inertia and the share of it beyond an F/T sensor at the start posture, the estimator's encoder and F/T
filters, the config's contacts and position feedback); :func:`predicted_radii` returns each loop's spectral radius
at the configured k_p, K6 and K7; :func:`check_predicted_stable` refuses a config whose model predicts a loop that
grows faster than :data:`RHO_MAX` per period, naming the motor file, the joint and the fields; :func:`tuned` does
both, for every path that builds the controller from a config file (``ControlManager.from_toml``, tasks,
experiments).

:func:`schedule_gains` (``gain_schedule = "margin"``) lowers each joint's k_p (halved, then 0) until the worst
radius over servos that differ from the model (:data:`~.stability.MISMATCH`) is at most :data:`RHO_TARGET`,
keeping K6 and K7: the torque feedback is what the estimator's filters turn into positive feedback at the joint's
resonance (the F/T path, the acceleration filter's phase), so it is the gain to give up where the margin is short.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from servotau.errors import ConfigError

from .stability import LoopModel, radius, worst_radius

# [-] per period. The linear loop leaves out friction and the dead band, which damp slow oscillations: measured on
# the simulated HRP-2, the nominal servo's hip yaw at the paper's position feedback (q_hat) and K6 = 0.5, predicted
# at 1.0054, runs; the family's K6 = 1 trips were predicted at 1.011 (hip pitch), 1.0145 (hip roll), 1.028 (ankle
# roll).
RHO_MAX = 1.008
RHO_TARGET = 0.997  # [-] per period, over MISMATCH: the margin the k_p schedule keeps
SCHEDULE_MISMATCH = ((1.0, 1.0), (1.25, 0.8), (0.8, 1.25))  # (k_tau, k_v) of the true servo / the model's


def joint_inertias(info, joints, posture=None) -> dict[str, float]:
    """Diagonal of the fixed-base joint-space mass matrix [kg m^2] (with the rotors' armature when the model has
    it) at ``posture`` [rad] (RobotInfo order; None: the model's neutral posture), per joint of ``joints``."""
    return {j: v[0] for j, v in _inertias(info, joints, posture).items()}


def _inertias(info, joints, posture=None, estimator=None) -> dict[str, tuple[float, float, tuple[str, ...]]]:
    """Per joint: (inertia [kg m^2], its share beyond F/T sensors [kg m^2], those sensors), at ``posture``."""
    import pinocchio as pin

    from servotau.estimation.model import EstimatorModel

    em = EstimatorModel(info, estimator or _estimator())
    m = em.model
    q = pin.neutral(m)
    ids = [int(j) for j in em.joints.joint_ids]
    if posture is not None:
        for i, jid in enumerate(ids):
            q[m.idx_qs[jid]] = float(posture[i])
    full = pin.crba(m, m.createData(), q)
    beyond = {}
    for s, ft in zip(info.ft_sensor_names, em.ft, strict=True):  # the mass matrix without that sensor's bodies
        light = m.copy()
        for k in (ft.joint_id, *ft.distal_joints):
            light.inertias[k] = pin.Inertia.Zero()
        beyond[s] = full - pin.crba(light, light.createData(), q)
    out = {}
    for j in joints:
        v = m.idx_vs[ids[info.joint_names.index(j)]]
        sensors = tuple(s for s, d in beyond.items() if d[v, v] > 1e-9)
        out[j] = (float(full[v, v]), float(sum(beyond[s][v, v] for s in sensors)), sensors)
    return out


def loop_models(config, info, estimator=None, posture=None) -> dict[str, LoopModel]:
    """Each torque joint's :class:`~.stability.LoopModel` at ``posture`` [rad] (None: the neutral posture)."""
    est = estimator or _estimator()
    inert = _inertias(info, config.torque_joints, posture, est)
    enc, ft = est.encoders, est.ft
    out = {}
    for j in config.gains:
        m = config.motors[j]
        inertia, ft_inertia, sensors = inert[j]
        out[j] = LoopModel(m.k_tau, m.k_v, inertia, info.period, int(enc.window), int(enc.order),
                           ft_inertia=ft_inertia, ft_window=int(ft.window), ft_order=int(ft.order),
                           contact=any(s in config.contacts for s in sensors),
                           encoder_position=config.position_feedback == "encoder")
    return out


def _servo_gains(config, j: str) -> tuple[float, float, float]:
    """(K6 [-], K7 [s], k_p [-]) of joint ``j``."""
    from .gains import k6_from_ks, k7_from_kd

    m, g = config.motors[j], config.gains[j]
    return float(k6_from_ks(m.k_tau, g.k_p, g.k_s)[0]), float(k7_from_kd(m.k_tau, g.k_p, g.k_d)[0]), g.k_p


def predicted_radii(config, info, estimator=None, posture=None) -> dict[str, float]:
    """Spectral radius of each torque joint's linearised loop at the config's gains (:mod:`.stability`)."""
    models = loop_models(config, info, estimator, posture)
    return {j: radius(lm, *_servo_gains(config, j)) for j, lm in models.items()}


class UnstableLoopError(ConfigError):
    """The identified model predicts that a joint's torque loop diverges at the configured gains."""


def check_predicted_stable(config, info, motors_file: str, estimator=None, posture=None) -> Mapping[str, float]:
    """:func:`predicted_radii`, or an :class:`UnstableLoopError` naming ``motors_file``, the joint, its k_tau and
    k_v and the gains when one exceeds :data:`RHO_MAX`."""
    radii = predicted_radii(config, info, estimator, posture)
    for j, rho in radii.items():
        if not (np.isfinite(rho) and rho <= RHO_MAX):
            m, g = config.motors[j], config.gains[j]
            raise UnstableLoopError(
                f"{motors_file}: joint \"{j}\": fields 'joints.{j}.k_tau' = {m.k_tau:.4g}, 'joints.{j}.k_v' = "
                f"{m.k_v:.4g} with k_p = {g.k_p:g}, k_s = {g.k_s:.4g} N m/rad, k_d = {g.k_d:.4g} N m s/rad: the model "
                f"predicts an unstable torque loop (spectral radius {rho:.4f} per period): expected at most "
                f"{RHO_MAX} (a servo model the controller can hold: k_tau, k_v as identified by servotau identify)")
    return radii


def schedule_gains(config, info, estimator=None, posture=None):
    """``config`` with each torque joint's k_p the largest of (k_p, k_p / 2, k_p / 4, 0) whose loop keeps
    :data:`RHO_TARGET` over :data:`SCHEDULE_MISMATCH` (0 if none does), K6 and K7 kept (k_s and k_d rescaled by
    ``(1 + k_p) / (1 + k_p_new)``). Unchanged unless ``config.gain_schedule == "margin"``."""
    if config.gain_schedule != "margin":
        return config
    models = loop_models(config, info, estimator, posture)
    gains = dict(config.gains)
    for j, lm in models.items():
        k6, k7, k_p = _servo_gains(config, j)
        chosen = 0.0
        for cand in (k_p, k_p / 2.0, k_p / 4.0):
            if cand > 0 and worst_radius(lm, k6, k7, cand, SCHEDULE_MISMATCH) <= RHO_TARGET:
                chosen = cand
                break
        g = gains[j]
        scale = (1.0 + g.k_p) / (1.0 + chosen)
        gains[j] = dataclasses.replace(g, k_p=chosen, k_s=g.k_s * scale, k_d=g.k_d * scale)
    return dataclasses.replace(config, gains=gains)


def tuned(config, info, motors_file: str, posture=None, estimator=None):
    """``config`` as the controller runs it: k_p scheduled (:func:`schedule_gains`, when the config says
    ``gain_schedule = "margin"``), then checked (:func:`check_predicted_stable`, naming ``motors_file``), at
    ``posture`` (n,) [rad] (None: the model's neutral posture). Every path that builds the controller from a
    config file goes through this.

    Raises:
        UnstableLoopError: The identified model predicts an unstable torque loop at the gains.
    """
    config = schedule_gains(config, info, estimator, posture)
    check_predicted_stable(config, info, motors_file, estimator, posture)
    return config


def _estimator():
    """The control loop's estimator config (its variant's filters)."""
    from .estimator_variant import estimator_config

    return estimator_config()
