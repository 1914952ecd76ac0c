"""The robot model in the simulator: MuJoCo loading, and the MuJoCo <-> Pinocchio state conversions.

The model file, the names of joints and sensors and the Pinocchio loader live in
:mod:`servotau.description` (the estimator and the controller read them from there, without MuJoCo).

State conventions of the two libraries for the free-floating base (the ``root`` joint):

- MuJoCo ``qpos[0:7] = [x, y, z, qw, qx, qy, qz]`` (quaternion wxyz); ``qvel[0:3]`` is the linear velocity
  of the base origin in the *world* frame and ``qvel[3:6]`` the angular velocity in the *base* frame.
- Pinocchio ``q[0:7] = [x, y, z, qx, qy, qz, qw]`` (quaternion xyzw); ``v[0:6]`` is the base twist, linear
  then angular, both in the *base* frame.

Hence ``qvel = J v`` with ``J = blockdiag(R, I)`` (``R`` the base orientation in world), so generalized
forces map as ``tau_pin = J^T tau_mj`` and mass matrices as ``M_pin = J^T M_mj J``. Joints are matched
by name, never by index.

F/T sensors: MuJoCo's ``<force>``/``<torque>`` sensors on a site return the wrench that the parent body
(proximal side) exerts on the site's body (distal side), in the site frame at the site origin. The HAL
convention (hal/types.py) is the opposite, distal on proximal, so :func:`mujoco_wrench_to_hal` flips the
sign (checked by tests/test_simrobot_model.py with a hanging foot and a standing robot).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import mujoco
import numpy as np
import pinocchio as pin

from servotau.description import HALF_SITTING, JOINT_NAMES, MODEL_PATH, ROOT_JOINT, load_pinocchio
from servotau.description.pinocchio_model import existing_model_file
from servotau.errors import ConfigError, ServotauError

MUJOCO_TO_HAL_WRENCH_SIGN = -1.0
"""MuJoCo's force/torque sensors give proximal-on-distal; the HAL wants distal-on-proximal."""


def mujoco_wrench_to_hal(wrench: np.ndarray) -> np.ndarray:
    """Convert MuJoCo F/T readings to HAL wrenches.

    Args:
        wrench: [N, N m] (..., 6) the ``<force>`` reading then the ``<torque>`` reading of one site (or
            a stack of sites), in the site frame at the site origin (MuJoCo: proximal on distal).

    Returns:
        [N, N m] (..., 6) ``[fx, fy, fz, tx, ty, tz]``: the wrench that the distal side exerts on the
        proximal side, in the sensor (site) frame at its origin.
    """
    w = np.asarray(wrench, dtype=float)
    if w.shape[-1:] != (6,):
        raise ServotauError(f"wrench has shape {w.shape}: expected (..., 6) [force, torque]")
    return MUJOCO_TO_HAL_WRENCH_SIGN * w


def load_mujoco(path: str | Path = MODEL_PATH) -> mujoco.MjModel:
    """Compile the MJCF file ``path`` with MuJoCo."""
    path = existing_model_file(path)
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as err:
        raise ConfigError(f"{path}: MuJoCo cannot compile the model: {err}") from err


@dataclass(frozen=True)
class JointMap:
    """Where each joint of :data:`JOINT_NAMES` lives in MuJoCo's and Pinocchio's state vectors."""

    mj_root_qpos: int  # qpos address of the free joint (7 values)
    mj_root_dof: int  # dof address of the free joint (6 values)
    mj_qpos: np.ndarray  # (30,) qpos address of each joint, JOINT_NAMES order
    mj_dof: np.ndarray  # (30,) qvel address of each joint
    pin_q: np.ndarray  # (30,) index in Pinocchio's q
    pin_v: np.ndarray  # (30,) index in Pinocchio's v
    nq: int  # 37, same in both
    nv: int  # 36, same in both

    @classmethod
    def from_models(cls, mj_model: mujoco.MjModel, pin_model: pin.Model) -> JointMap:
        """Match the joints of the two models by name; raise ConfigError if they differ."""
        root = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_JOINT, ROOT_JOINT)
        if root < 0 or mj_model.jnt_type[root] != mujoco.mjtJoint.mjJNT_FREE:
            raise ConfigError(f'MuJoCo model: expected a free joint named "{ROOT_JOINT}"')
        if pin_model.getJointId(ROOT_JOINT) != 1 or pin_model.idx_qs[1] != 0 or pin_model.idx_vs[1] != 0:
            raise ConfigError(f'Pinocchio model: expected the free flyer "{ROOT_JOINT}" first')
        mj_qpos, mj_dof, pin_q, pin_v = [], [], [], []
        for name in JOINT_NAMES:
            j = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_JOINT, name)
            if j < 0 or mj_model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
                raise ConfigError(f'MuJoCo model: joint "{name}" missing or not a hinge')
            k = pin_model.getJointId(name)
            if k >= pin_model.njoints or pin_model.nqs[k] != 1 or pin_model.nvs[k] != 1:
                raise ConfigError(f'Pinocchio model: joint "{name}" missing or not 1-dof')
            mj_qpos.append(mj_model.jnt_qposadr[j])
            mj_dof.append(mj_model.jnt_dofadr[j])
            pin_q.append(pin_model.idx_qs[k])
            pin_v.append(pin_model.idx_vs[k])
        expected = (7 + len(JOINT_NAMES), 6 + len(JOINT_NAMES))
        for who, sizes in (("MuJoCo", (mj_model.nq, mj_model.nv)), ("Pinocchio", (pin_model.nq, pin_model.nv))):
            if sizes != expected:
                raise ConfigError(f"{who} model: (nq, nv) = {sizes}, expected {expected}")
        arr = [np.array(a, dtype=int) for a in (mj_qpos, mj_dof, pin_q, pin_v)]
        for a in arr:
            a.setflags(write=False)
        return cls(int(mj_model.jnt_qposadr[root]), int(mj_model.jnt_dofadr[root]), *arr, *expected)


@lru_cache(maxsize=1)
def default_joint_map() -> JointMap:
    """The :class:`JointMap` of :data:`MODEL_PATH` (built once)."""
    return JointMap.from_models(load_mujoco(), load_pinocchio())


class PinocchioState(NamedTuple):
    """Pinocchio configuration and velocity (unpacks as ``q, v``)."""

    q: np.ndarray  # (37,) [m, quaternion xyzw, rad]
    v: np.ndarray  # (36,) [m/s, rad/s] base twist in the base frame, then joint velocities


class MujocoState(NamedTuple):
    """MuJoCo ``qpos`` and ``qvel`` (unpacks as ``qpos, qvel``)."""

    qpos: np.ndarray  # (37,) [m, quaternion wxyz, rad]
    qvel: np.ndarray  # (36,) [m/s world frame, rad/s base frame, rad/s]


def base_rotation_wxyz(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a quaternion ``[w, x, y, z]`` (normalized first)."""
    w, x, y, z = _vec(quat_wxyz, 4, "quat_wxyz") / np.linalg.norm(quat_wxyz)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def mujoco_to_pinocchio_state(qpos: np.ndarray, qvel: np.ndarray, joint_map: JointMap | None = None
                              ) -> PinocchioState:
    """Convert MuJoCo ``(qpos, qvel)`` to Pinocchio ``(q, v)``.

    The quaternion is normalized (MuJoCo tolerates drift, Pinocchio assumes a unit quaternion).
    """
    jm = joint_map or default_joint_map()
    qpos, qvel = _vec(qpos, jm.nq, "qpos"), _vec(qvel, jm.nv, "qvel")
    r, d = jm.mj_root_qpos, jm.mj_root_dof
    quat = qpos[r + 3 : r + 7] / np.linalg.norm(qpos[r + 3 : r + 7])
    rot = base_rotation_wxyz(quat)
    q, v = np.zeros(jm.nq), np.zeros(jm.nv)
    q[0:3] = qpos[r : r + 3]
    q[3:7] = quat[[1, 2, 3, 0]]
    q[jm.pin_q] = qpos[jm.mj_qpos]
    v[0:3] = rot.T @ qvel[d : d + 3]
    v[3:6] = qvel[d + 3 : d + 6]
    v[jm.pin_v] = qvel[jm.mj_dof]
    return PinocchioState(q, v)


def pinocchio_to_mujoco_state(q: np.ndarray, v: np.ndarray, joint_map: JointMap | None = None) -> MujocoState:
    """Convert Pinocchio ``(q, v)`` to MuJoCo ``(qpos, qvel)`` (inverse of :func:`mujoco_to_pinocchio_state`)."""
    jm = joint_map or default_joint_map()
    q, v = _vec(q, jm.nq, "q"), _vec(v, jm.nv, "v")
    r, d = jm.mj_root_qpos, jm.mj_root_dof
    quat = q[[6, 3, 4, 5]] / np.linalg.norm(q[3:7])
    qpos, qvel = np.zeros(jm.nq), np.zeros(jm.nv)
    qpos[r : r + 3] = q[0:3]
    qpos[r + 3 : r + 7] = quat
    qpos[jm.mj_qpos] = q[jm.pin_q]
    qvel[d : d + 3] = base_rotation_wxyz(quat) @ v[0:3]
    qvel[d + 3 : d + 6] = v[3:6]
    qvel[jm.mj_dof] = v[jm.pin_v]
    return MujocoState(qpos, qvel)


def mujoco_to_pinocchio_acceleration(qpos: np.ndarray, qvel: np.ndarray, qacc: np.ndarray,
                                     joint_map: JointMap | None = None) -> np.ndarray:
    """Convert MuJoCo ``qacc`` (the time derivative of ``qvel``) to Pinocchio ``a`` (that of ``v``).

    With ``v_lin = R^T qvel_lin``: ``a_lin = R^T qacc_lin - omega x v_lin`` (all in the base frame).

    Returns:
        (36,) [m/s^2, rad/s^2] Pinocchio acceleration.
    """
    jm = joint_map or default_joint_map()
    _, v = mujoco_to_pinocchio_state(qpos, qvel, jm)
    qacc = _vec(qacc, jm.nv, "qacc")
    d = jm.mj_root_dof
    rot = base_rotation_wxyz(_vec(qpos, jm.nq, "qpos")[jm.mj_root_qpos + 3 : jm.mj_root_qpos + 7])
    a = np.zeros(jm.nv)
    a[0:3] = rot.T @ qacc[d : d + 3] - np.cross(v[3:6], v[0:3])
    a[3:6] = qacc[d + 3 : d + 6]
    a[jm.pin_v] = qacc[jm.mj_dof]
    return a


def mujoco_to_pinocchio_force(qpos: np.ndarray, qfrc: np.ndarray, joint_map: JointMap | None = None
                              ) -> np.ndarray:
    """Convert a MuJoCo generalized force (e.g. ``qfrc_inverse``) to Pinocchio's ``tau = J^T qfrc``.

    Returns:
        (36,) [N, N m] base force and torque in the base frame, then joint torques.
    """
    jm = joint_map or default_joint_map()
    qfrc = _vec(qfrc, jm.nv, "qfrc")
    d = jm.mj_root_dof
    rot = base_rotation_wxyz(_vec(qpos, jm.nq, "qpos")[jm.mj_root_qpos + 3 : jm.mj_root_qpos + 7])
    tau = np.zeros(jm.nv)
    tau[0:3] = rot.T @ qfrc[d : d + 3]
    tau[3:6] = qfrc[d + 3 : d + 6]
    tau[jm.pin_v] = qfrc[jm.mj_dof]
    return tau


def mujoco_to_pinocchio_mass_matrix(qpos: np.ndarray, mass_matrix: np.ndarray,
                                    joint_map: JointMap | None = None) -> np.ndarray:
    """Convert MuJoCo's dense mass matrix (``mj_fullM``) to Pinocchio's: ``M_pin = J^T M_mj J``."""
    jm = joint_map or default_joint_map()
    m_mj = np.asarray(mass_matrix, dtype=float)
    if m_mj.shape != (jm.nv, jm.nv):
        raise ServotauError(f"mass_matrix has shape {m_mj.shape}: expected ({jm.nv}, {jm.nv})")
    d = jm.mj_root_dof
    jac = np.zeros((jm.nv, jm.nv))  # qvel = jac @ v
    jac[d : d + 3, 0:3] = base_rotation_wxyz(_vec(qpos, jm.nq, "qpos")[jm.mj_root_qpos + 3 : jm.mj_root_qpos + 7])
    jac[d + 3 : d + 6, 3:6] = np.eye(3)
    jac[jm.mj_dof, jm.pin_v] = 1.0
    return jac.T @ m_mj @ jac


def keyframe_qpos(mj_model: mujoco.MjModel, name: str) -> np.ndarray:
    """MuJoCo ``qpos`` (37,) of keyframe ``name`` (a copy) [m, quaternion wxyz, rad]."""
    key = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_KEY, name)
    if key < 0:
        names = [mj_model.key(k).name for k in range(mj_model.nkey)]
        raise ConfigError(f'the robot model has no keyframe "{name}": expected one of {names}')
    return np.array(mj_model.key_qpos[key])


def half_sitting_qpos(mj_model: mujoco.MjModel | None = None) -> np.ndarray:
    """MuJoCo ``qpos`` (37,) of the ``half_sitting`` keyframe [m, quaternion wxyz, rad]."""
    return keyframe_qpos(mj_model if mj_model is not None else load_mujoco(), HALF_SITTING)


def _vec(x: np.ndarray, n: int, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.shape != (n,):
        raise ServotauError(f"{name} has shape {arr.shape}: expected ({n},)")
    return arr
