"""Tests of servotau.control.law: the full law and its split into the paper's components (eq. 13-14, section 5.5)."""

import numpy as np
import pytest

from servotau.actuator import MotorParameters
from servotau.config import CONFIG_DIR
from servotau.control.config import ControlConfig, ForceTask, JointGains, SafetyLimits
from servotau.control.gains import k9_from_kf
from servotau.control.law import TorqueControlLaw
from servotau.description import JOINT_NAMES, MODEL_PATH
from servotau.simrobot.model import default_joint_map, half_sitting_qpos

LEG = [f"RLEG_JOINT{i}" for i in range(6)]


def _config(force=True, k_i=0.0, velocity_feedforward="estimate", k_iq=0.0):
    motors = MotorParameters.load_toml(CONFIG_DIR / "motors" / "example.toml")
    gains = {j: JointGains(k_p=2.0, k_s=500.0 + 100 * i, k_d=5.0 + i, k_i=k_i, integral_limit=3.0, k_iq=k_iq)
             for i, j in enumerate(LEG)}
    task = ForceTask("right_ankle", "ft_right_ankle", axes=("fx", "fz", "ty"), k_f=(0.5, 1.0, 0.2)) if force else None
    return ControlConfig(JOINT_NAMES, gains, motors, SafetyLimits.uniform(30), contacts=("right_ankle",), force=task,
                         velocity_feedforward=velocity_feedforward)


def _inputs(seed=0):
    rng = np.random.default_rng(seed)
    q = half_sitting_qpos()[default_joint_map().mj_qpos]
    q_hat = q + rng.normal(0, 0.01, 30)
    dq_hat, ddq_hat = rng.normal(0, 0.3, 30), rng.normal(0, 3, 30)
    w = rng.normal(0, 5, (4, 6))
    w[0, 2] = 120.0
    return q_hat, dq_hat, ddq_hat, q, rng.normal(0, 0.3, 30), rng.normal(0, 3, 30), w, rng


@pytest.mark.parametrize("force, k_i, k_iq", [(True, 0.0, 0.0), (False, 0.0, 0.0), (True, 5.0, 0.0), (True, 0.0, 50.0),
                                             (False, 0.0, 50.0)])
def test_components_sum_to_the_command(force, k_i, k_iq):
    """ff_torque + ff_friction + fb_* (+ residual, integrals) equals dq_err exactly, with and without force task."""
    law = TorqueControlLaw(_config(force, k_i, k_iq=k_iq), str(MODEL_PATH), 1e-3)
    terms = law.make_terms()
    q_hat, dq_hat, ddq_hat, q_d, dq_d, ddq_d, w, rng = _inputs()
    dq_d[:3] = 0.0  # the position integral runs where the reference is at rest
    if force:
        law.inverse_dynamics.set_force_reference([10.0, 0.0, 150.0, 0.0, 2.0, 0.0])
    for _ in range(3):
        tau_hat = rng.normal(0, 20, 30)
        dq_err = law.update(terms, q_hat, dq_hat, ddq_hat, tau_hat, q_d, dq_d, ddq_d, w)
    np.testing.assert_allclose(terms.component_sum(), dq_err, atol=1e-15)
    assert np.abs(dq_err[:6]).min() > 0 and not dq_err[6:].any()
    # example.toml has a deadzone term on the ankle roll only: its own component, streamed like the others
    assert terms.ff_extra[5] != 0 and not terms.ff_extra[:5].any() and not terms.ff_extra[6:].any()
    assert np.abs(terms.fb_integral).max() > 0 if k_i else not terms.fb_integral.any()
    assert np.abs(terms.fb_position_integral).max() > 0 if k_iq else not terms.fb_position_integral.any()
    if k_iq and force:  # its torque is out of the force task's directions
        np.testing.assert_allclose(law.inverse_dynamics.task_jacobian @ law.position_integral.tau, 0.0, atol=1e-9)


def test_components_are_k6_to_k9_of_the_paper():
    """The fb_* terms are K6 e_q, K7 de_q, K8 dde_q, K9 e_f; the residual is 0 if tau_hat is the model's torque."""
    cfg = _config()
    law = TorqueControlLaw(cfg, str(MODEL_PATH), 1e-3)
    terms = law.make_terms()
    q_hat, dq_hat, ddq_hat, q_d, dq_d, ddq_d, w, _ = _inputs(seed=2)
    law.inverse_dynamics.set_force_reference([10.0, 0.0, 150.0, 0.0, 2.0, 0.0])
    idc = law.inverse_dynamics
    # tau_hat = M ddq_hat + h - J^T f_hat: the paper's assumption, which makes the residual vanish.
    law.update(terms, q_hat, dq_hat, ddq_hat, np.zeros(30), q_d, dq_d, ddq_d, w)
    tau_model = idc.b_hat - idc.jtf_hat
    law.update(terms, q_hat, dq_hat, ddq_hat, tau_model, q_d, dq_d, ddq_d, w)
    leg = slice(0, 6)
    k_tau, k_p = cfg.motor_vector("k_tau")[leg], cfg.joint_vector("k_p")[leg]
    k_s, k_d = cfg.joint_vector("k_s")[leg], cfg.joint_vector("k_d")[leg]
    mass = idc.dyn.mass_matrix()[leg, :]  # joint rows of the leg, all columns
    np.testing.assert_allclose(terms.fb_position[leg], k_tau * (1 + k_p) * k_s * (q_d - q_hat)[leg], rtol=1e-12)
    np.testing.assert_allclose(terms.fb_velocity[leg], k_tau * (1 + k_p) * k_d * (dq_d - dq_hat)[leg], rtol=1e-12)
    np.testing.assert_allclose(terms.fb_acceleration[leg], (k_tau * k_p)[:, None] * mass @ (ddq_d - ddq_hat),
                               rtol=1e-9, atol=1e-15)
    axes = cfg.force.axis_index
    jac = idc.task_jacobian[:, leg]
    k9 = k9_from_kf(k_tau, k_p, jac, np.array(cfg.force.k_f))
    np.testing.assert_allclose(terms.fb_force[leg], k9 @ terms.e_f[axes], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(terms.fb_torque_residual, 0.0, atol=1e-15)
    f_ff = w[0].copy()
    f_ff[axes] = idc.f_d[axes]
    expected_ff = k_tau * (idc.b_d - idc.contact_jacobian("right_ankle").T @ f_ff)[leg]
    np.testing.assert_allclose(terms.ff_torque[leg], expected_ff, rtol=1e-9)


def test_terms_share_the_law_buffers():
    """make_terms() exposes the law's own arrays (no copy per tick): tau_d and tau_star are the same objects."""
    law = TorqueControlLaw(_config(False), str(MODEL_PATH), 1e-3)
    terms = law.make_terms()
    assert terms.tau_d is law.inverse_dynamics.tau_d
    assert terms.tau_star is law.torque.tau_star
    law.clear(terms)
    assert not any(v.any() for v in terms.components().values())


@pytest.mark.parametrize("source", ["estimate", "reference", "reference_signs"])
def test_velocity_feedforward_reads_the_configured_velocity(source):
    """ff_friction is K_v dq + k_c tanh(dq / v_s) on dq_hat ("estimate") or dq_d ("reference"), or K_v dq_hat +
    k_c tanh(dq_d / v_s) ("reference_signs"); fb_* keep dq_hat."""
    cfg = _config(force=False, velocity_feedforward=source)
    law = TorqueControlLaw(cfg, str(MODEL_PATH), 1e-3)
    terms = law.make_terms()
    q_hat, dq_hat, ddq_hat, q_d, dq_d, ddq_d, w, rng = _inputs(seed=3)
    dq_err = law.update(terms, q_hat, dq_hat, ddq_hat, rng.normal(0, 20, 30), q_d, dq_d, ddq_d, w)
    dq_ff = dq_d if source == "reference" else dq_hat
    dq_sign = dq_hat if source == "estimate" else dq_d
    k_v, k_c = cfg.motor_vector("k_v"), cfg.motor_vector("k_c")
    expected = k_v * dq_ff + k_c * np.tanh(dq_sign / cfg.sign_velocity)
    np.testing.assert_allclose(terms.ff_friction[:5], expected[:5], rtol=1e-12)  # joint 5 has extra terms
    assert np.abs(terms.ff_friction[:5]).min() > 0
    np.testing.assert_allclose(terms.fb_velocity, law.k7 * (dq_d - dq_hat), rtol=1e-12)
    np.testing.assert_allclose(terms.component_sum(), dq_err, atol=1e-15)


def test_set_gains_writes_in_place_ramps_and_names_a_bad_joint():
    """New gains land in the law's own arrays (the terms and the position integral see them), ramped half-cosine over
    ``ramp`` (each tick moves the command by a fraction of the change), equal to a law built with them once the ramp
    is over; a bad gain names the joint and changes nothing; entering torque mode (reset) completes a ramp."""
    from dataclasses import replace

    config = _config(force=False, k_iq=50.0)
    law = TorqueControlLaw(config, str(MODEL_PATH), 1e-3)
    k_s_id, k6_id = id(law.inverse_dynamics.k_s), id(law.k6)
    soft = replace(config, gains={j: replace(g, k_p=1.0, k_s=g.k_s / 2, k_d=g.k_d * 2)
                                  for j, g in config.gains.items()})
    ref = TorqueControlLaw(soft, str(MODEL_PATH), 1e-3)
    q_hat, dq_hat, ddq_hat, q_d, dq_d, ddq_d, w, rng = _inputs()
    tau_hat = rng.normal(0, 20, 30)
    terms, ref_terms = law.make_terms(), ref.make_terms()
    old = law.update(terms, q_hat, dq_hat, ddq_hat, tau_hat, q_d, dq_d, ddq_d, w).copy()
    with pytest.raises(Exception, match=r"set_gains: joint RLEG_JOINT2: k_s = -1.0: expected a finite number >= 0"):
        law.set_gains(*soft_gains(soft, k_s={2: -1.0}))
    with pytest.raises(Exception, match=r"set_gains: joint HEAD_JOINT0: k_p = 1.0: expected 0 \(a position-control"):
        law.set_gains(*soft_gains(soft, k_p={JOINT_NAMES.index("HEAD_JOINT0"): 1.0}))
    law.set_gains(*soft_gains(soft), ramp=0.01)  # 10 ticks
    outs = [law.update(terms, q_hat, dq_hat, ddq_hat, tau_hat, q_d, dq_d, ddq_d, w).copy() for _ in range(12)]
    new = ref.update(ref_terms, q_hat, dq_hat, ddq_hat, tau_hat, q_d, dq_d, ddq_d, w)
    assert id(law.inverse_dynamics.k_s) == k_s_id and id(law.k6) == k6_id
    np.testing.assert_allclose(law.inverse_dynamics.k_s, ref.inverse_dynamics.k_s)
    np.testing.assert_allclose(law.position_integral.k_s, ref.position_integral.k_s)
    np.testing.assert_allclose(law.k6, ref.k6)
    steps = np.abs(np.diff([old, *outs], axis=0)).max(axis=1)
    jump = np.abs(new - old).max()
    assert steps.max() < 0.2 * jump  # no step: the change spread over the ramp (half-cosine, 10 ticks: <= 16 %)
    law.set_gains(*soft_gains(config), ramp=1.0)
    law.reset()
    np.testing.assert_allclose(law.k6, TorqueControlLaw(config, str(MODEL_PATH), 1e-3).k6)


def soft_gains(config, **overrides):
    """(k_p, k_s, k_d) vectors of ``config``, with ``{name: {index: value}}`` overrides."""
    out = []
    for name in ("k_p", "k_s", "k_d"):
        v = config.joint_vector(name)
        for i, x in overrides.get(name, {}).items():
            v[i] = x
        out.append(v)
    return out


def test_encoder_position_feedback_reads_the_measured_angles_and_the_components_still_sum():
    """position_feedback = "encoder": e_q = q_d - q (the frame's angles), the command moves by K6 (q_hat - q) and
    the components still sum to it; "estimate" (the paper) keeps q_hat."""
    import dataclasses

    cfg = _config(force=False)
    q_hat, dq_hat, ddq_hat, q_d, dq_d, ddq_d, w, rng = _inputs()
    q_enc = q_hat + rng.normal(0, 0.002, 30)
    tau_hat = rng.normal(0, 20, 30)
    out = {}
    for mode in ("estimate", "encoder"):
        law = TorqueControlLaw(dataclasses.replace(cfg, position_feedback=mode), str(MODEL_PATH), 1e-3)
        terms = law.make_terms()
        out[mode] = law.update(terms, q_hat, dq_hat, ddq_hat, tau_hat, q_d, dq_d, ddq_d, w, q_encoder=q_enc).copy()
        np.testing.assert_allclose(terms.component_sum(), out[mode], atol=1e-15)
        np.testing.assert_allclose(terms.e_q, q_d - (q_enc if mode == "encoder" else q_hat))
    np.testing.assert_allclose(out["encoder"] - out["estimate"], law.k6 * (q_hat - q_enc), atol=1e-12)
