"""Tests of servotau.control.inverse_dynamics: the desired torques of the paper's eq. 12."""

import mujoco
import numpy as np
import pytest

from servotau.control.config import ForceTask
from servotau.control.dynamics import RobotDynamics
from servotau.control.inverse_dynamics import InverseDynamics
from servotau.description import JOINT_NAMES, MODEL_PATH
from servotau.errors import ControlError
from servotau.simrobot.model import default_joint_map, half_sitting_qpos, load_mujoco

Z = np.zeros(30)


def _reference_model():
    """MuJoCo at half-sitting (base upright, at rest): gravity torques and the right-ankle site's J^T."""
    jm = default_joint_map()
    m = load_mujoco()
    d = mujoco.MjData(m)
    d.qpos[:] = half_sitting_qpos(m)
    mujoco.mj_forward(m, d)

    def jt(f, name="ft_right_ankle"):  # J^T f for a wrench f in the frame of site ``name``
        site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)
        jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jacSite(m, d, jacp, jacr, site)
        rot = d.site_xmat[site].reshape(3, 3)
        return (jacp.T @ (rot @ f[:3]) + jacr.T @ (rot @ f[3:]))[jm.mj_dof]

    return d.qpos[jm.mj_qpos].copy(), d.qfrc_bias[jm.mj_dof].copy(), jt


def _law(contacts=(), force=None, k_s=None, k_d=None):
    dyn = RobotDynamics(MODEL_PATH, JOINT_NAMES, "fixed")
    return InverseDynamics(dyn, Z if k_s is None else k_s, Z if k_d is None else k_d, contacts, force)


def test_reproduces_the_gravity_torque_at_rest():
    """At rest on the reference (e_q = 0), tau_d is the model's gravity torque, whatever the gains."""
    q, gravity, _ = _reference_model()
    law = _law(k_s=np.full(30, 5000.0), k_d=np.full(30, 50.0))
    tau_d = law.update(q, Z, Z, q, Z, Z)
    np.testing.assert_allclose(tau_d, gravity, atol=1e-9)
    assert abs(gravity[JOINT_NAMES.index("RLEG_JOINT3")]) > 1.0


def test_stiffness_and_damping_add_ks_eq_plus_kd_deq():
    """tau_d - gravity = K_s e_q + K_d de_q (the state, hence gravity, is unchanged)."""
    q, gravity, _ = _reference_model()
    k_s, k_d = np.linspace(100, 3000, 30), np.linspace(1, 30, 30)
    law = _law(k_s=k_s, k_d=k_d)
    e_q, de_q = np.linspace(-0.01, 0.01, 30), np.linspace(0.2, -0.2, 30)
    tau_d = law.update(q, Z, Z, q + e_q, de_q, Z)
    np.testing.assert_allclose(tau_d - gravity, k_s * e_q + k_d * de_q, atol=1e-9)
    np.testing.assert_allclose(law.e_q, e_q)


def test_measured_contact_wrench_is_compensated():
    """With the right ankle as a contact, tau_d = gravity - J^T f_hat (J from MuJoCo)."""
    q, gravity, jt = _reference_model()
    w = np.zeros((4, 6))
    w[0] = [4.0, -3.0, 250.0, 2.0, -6.0, 0.3]
    law = _law(contacts=("right_ankle",))
    tau_d = law.update(q, Z, Z, q, Z, Z, wrenches=w)
    np.testing.assert_allclose(tau_d, gravity - jt(w[0]), atol=1e-8)
    with pytest.raises(ControlError, match="wrenches"):
        law.update(q, Z, Z, q, Z, Z)


@pytest.mark.parametrize("contacts", [(), ("left_ankle",), ("right_ankle", "left_ankle")])
def test_force_task_regulates_listed_axes_only(contacts):
    """Regulated axes get f* = f_d + K_f (f_d - f_hat); other axes and other contacts keep the measured wrench."""
    q, gravity, jt = _reference_model()
    w = np.zeros((4, 6))
    w[0] = [5.0, 0.0, 60.0, 0.0, 1.0, 0.0]
    w[1] = [1.0, 2.0, 250.0, 0.5, -0.5, 0.1]
    law = _law(contacts, force=ForceTask("right_ankle", "ft_right_ankle", axes=("fz",), k_f=(0.5,)))
    law.set_force_reference([99.0, 99.0, 100.0, 99.0, 99.0, 99.0])  # only fz is used
    for _ in range(2):
        tau_d = law.update(q, Z, Z, q, Z, Z, wrenches=w)
    f_star = w[0].copy()
    f_star[2] = 100.0 + 0.5 * (100.0 - 60.0)
    left = jt(w[1], "ft_left_ankle") if "left_ankle" in contacts else 0.0
    np.testing.assert_allclose(tau_d, gravity - jt(f_star) - left, atol=1e-8)
    np.testing.assert_allclose(law.e_f, [0, 0, 40.0, 0, 0, 0])
    np.testing.assert_allclose(law.jt_ef, jt(law.e_f), atol=1e-9)


def test_force_task_at_an_offset_frame_is_consistent():
    """A force task at the sole (offset frame) with f_d equal to the measured wrench there gives tau_d = g - J^T f."""
    q, gravity, jt = _reference_model()
    w = np.zeros((4, 6))
    w[0] = [5.0, 2.0, 300.0, 0.5, 1.0, 0.0]
    law = _law(force=ForceTask("right_ankle", "ft_right_ankle", offset=(0.0, 0.0, -0.02)))
    law.update(q, Z, Z, q, Z, Z, wrenches=w)
    law.set_force_reference(law.f_hat.copy())  # the measured wrench, moved to the sole
    tau_d = law.update(q, Z, Z, q, Z, Z, wrenches=w)
    np.testing.assert_allclose(law.e_f, 0.0, atol=1e-9)
    np.testing.assert_allclose(tau_d, gravity - jt(w[0]), atol=1e-8)
    np.testing.assert_allclose(law.f_hat[3:], w[0, 3:] - np.cross([0, 0, -0.02], w[0, :3]), atol=1e-12)


def test_bad_inputs_raise():
    """Gains of the wrong size or sign, a force reference without a task or a bad contact raise ControlError."""
    with pytest.raises(ControlError, match="k_s"):
        _law(k_s=-np.ones(30))
    with pytest.raises(ControlError, match="no force task"):
        _law().set_force_reference(np.zeros(6))
    with pytest.raises(ControlError, match="f_d"):
        _law(force=ForceTask()).set_force_reference([np.nan] * 6)
    with pytest.raises(ControlError, match="right_knee"):
        _law(contacts=("right_knee",))
