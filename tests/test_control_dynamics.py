"""Tests of servotau.control.dynamics: the controller's Pinocchio model against MuJoCo's (an independent library)."""

import mujoco
import numpy as np
import pytest

from servotau.control.dynamics import BaseState, RobotDynamics
from servotau.description import JOINT_NAMES, MODEL_PATH
from servotau.errors import ControlError
from servotau.simrobot.model import default_joint_map, half_sitting_qpos, load_mujoco


def _mujoco_at(qpos, qvel=None):
    m = load_mujoco()
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    if qvel is not None:
        d.qvel[:] = qvel
    mujoco.mj_forward(m, d)
    return m, d


def _half_sitting():
    jm = default_joint_map()
    qpos = half_sitting_qpos()
    return jm, qpos, qpos[jm.mj_qpos].copy()


@pytest.mark.parametrize("base", ["fixed", "floating"])
def test_gravity_torque_at_rest_matches_mujoco(base):
    """At rest in half-sitting, M a + h with a = 0 is MuJoCo's gravity torque (qfrc_bias) on every joint."""
    jm, qpos, q = _half_sitting()
    _, d = _mujoco_at(qpos)
    dyn = RobotDynamics(MODEL_PATH, JOINT_NAMES, base)
    upright = BaseState(np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 9.81]))
    dyn.set_state(q, np.zeros(30), upright)
    tau = dyn.inverse_dynamics(np.zeros(30), np.zeros(30))
    np.testing.assert_allclose(tau, d.qfrc_bias[jm.mj_dof], atol=1e-9)
    assert np.abs(tau[:12]).max() > 1.0  # the legs carry real load


def test_inertia_and_coriolis_match_mujoco_with_fixed_base():
    """With the base fixed, M ddq + h matches MuJoCo's inverse dynamics for a moving leg."""
    jm, qpos, q = _half_sitting()
    rng = np.random.default_rng(1)
    dq, ddq = rng.normal(0, 1, 30), rng.normal(0, 5, 30)
    m = load_mujoco()
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    d.qvel[jm.mj_dof] = dq
    d.qacc[jm.mj_dof] = ddq
    mujoco.mj_inverse(m, d)
    expected = d.qfrc_inverse[jm.mj_dof]  # base velocity and acceleration 0: the fixed-base joint torques
    dyn = RobotDynamics(MODEL_PATH, JOINT_NAMES, "fixed")
    dyn.set_state(q, dq)
    np.testing.assert_allclose(dyn.inverse_dynamics(ddq, np.zeros(30)), expected, atol=1e-8)
    np.testing.assert_allclose(dyn.mass_matrix()[:6, :6], _mujoco_mass(m, d, jm)[:6, :6], atol=1e-10)


def _mujoco_mass(m, d, jm):
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    return full[np.ix_(jm.mj_dof, jm.mj_dof)]


def test_site_jacobian_transpose_matches_mujoco():
    """J^T f of the right-ankle F/T frame (LOCAL) equals MuJoCo's site Jacobian applied to the same wrench."""
    jm, qpos, q = _half_sitting()
    m, d = _mujoco_at(qpos)
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "ft_right_ankle")
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jacp, jacr, site)
    rot = d.site_xmat[site].reshape(3, 3)
    f = np.array([3.0, -2.0, 150.0, 1.0, -4.0, 0.5])
    expected = (jacp.T @ (rot @ f[:3]) + jacr.T @ (rot @ f[3:]))[jm.mj_dof]
    dyn = RobotDynamics(MODEL_PATH, JOINT_NAMES, "fixed")
    dyn.set_state(q, np.zeros(30))
    jac = dyn.jacobian(dyn.frame_id("ft_right_ankle"), np.zeros((6, 30)))
    np.testing.assert_allclose(jac.T @ f, expected, atol=1e-9)


def test_offset_frame_and_wrench_transform_preserve_joint_torques():
    """A wrench moved to an offset frame on the same body gives the same J^T f."""
    dyn = RobotDynamics(MODEL_PATH, JOINT_NAMES, "fixed")
    sensor = dyn.frame_id("ft_right_ankle")
    sole = dyn.add_offset_frame("sole", "ft_right_ankle", [0.01, 0.0, -0.02])
    _, _, q = _half_sitting()
    dyn.set_state(q, np.zeros(30))
    f = np.array([10.0, 5.0, 200.0, 0.0, 1.0, 0.0])
    f_sole = dyn.wrench_transform(sensor, sole) @ f
    assert not np.allclose(f_sole[3:], f[3:])  # the torque changes with the point
    j_s = dyn.jacobian(sensor, np.zeros((6, 30)))
    j_t = dyn.jacobian(sole, np.zeros((6, 30)))
    np.testing.assert_allclose(j_t.T @ f_sole, j_s.T @ f, atol=1e-9)
    with pytest.raises(ControlError, match="same body"):
        dyn.wrench_transform(sensor, dyn.frame_id("ft_left_ankle"))


def test_pinocchio_data_is_allocated_once():
    """Ticks reuse the one pin.Data built at construction."""
    dyn = RobotDynamics(MODEL_PATH, JOINT_NAMES, "floating")
    data = dyn.data
    out, jac = np.zeros(30), np.zeros((6, 30))
    base = BaseState(np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 9.81]))
    for k in range(5):
        dyn.set_state(np.full(30, 0.01 * k), np.zeros(30), base)
        dyn.inverse_dynamics(np.zeros(30), out)
        dyn.jacobian(dyn.frame_id("ft_right_ankle"), jac)
    assert dyn.data is data


def test_bad_names_raise():
    """Unknown bases, joints and frames raise ControlError naming what was expected."""
    with pytest.raises(ControlError, match="expected one of"):
        RobotDynamics(MODEL_PATH, JOINT_NAMES, "wobbly")
    with pytest.raises(ControlError, match="KNEE"):
        RobotDynamics(MODEL_PATH, ("KNEE", *JOINT_NAMES[1:]), "fixed")
    with pytest.raises(ControlError, match="base state"):
        RobotDynamics(MODEL_PATH, JOINT_NAMES, "floating").set_state(np.zeros(30), np.zeros(30))
    with pytest.raises(ControlError, match="nose"):
        RobotDynamics(MODEL_PATH, JOINT_NAMES, "fixed").frame_id("nose")
