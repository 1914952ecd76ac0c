"""The 3D robot in Rerun as a transform tree.

Each MuJoCo body is an entity nested under its parent (``robot/BODY/RLEG_LINK0/...``); its geometry (boxes and
capsules, in the body frame) is logged once as static data under ``<body>/boxes`` and ``<body>/capsules``.
Per logged tick, each body
gets one Transform3D relative to its parent (translation [m], quaternion xyzw), buffered and sent in columns.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from servotau.errors import ConfigError

COLOR = (150, 160, 200)


class RobotTree:
    """Forward kinematics of the model at given joint angles, as per-body transforms relative to the parent."""

    def __init__(self, model_path: str, joint_names: Sequence[str], root: str = "robot"):
        m = self.model = mujoco.MjModel.from_xml_path(model_path)
        self.data = mujoco.MjData(m)
        model_joints = {m.joint(i).name for i in range(m.njnt)}
        unknown = [j for j in joint_names if j not in model_joints]
        if unknown:
            raise ConfigError(f"{model_path}: joints {unknown} are not in the model: expected names among "
                              f"{sorted(model_joints)}")
        self._qadr = np.array([m.joint(j).qposadr[0] for j in joint_names], dtype=int)
        self._free = any(m.jnt_type[i] == mujoco.mjtJoint.mjJNT_FREE for i in range(m.njnt))
        paths = {0: root}
        for b in range(1, m.nbody):
            paths[b] = f"{paths[int(m.body_parentid[b])]}/{m.body(b).name or f'body{b}'}"
        self.bodies = list(range(1, m.nbody))
        self.paths = [paths[b] for b in self.bodies]
        self.parents = np.array([int(m.body_parentid[b]) for b in self.bodies])

    def log_static(self, rec) -> None:
        """The geometry of every body, in its body frame, once: ``<body>/boxes``, ``<body>/capsules``."""
        import rerun as rr

        m = self.model
        paths = dict(zip(self.bodies, self.paths, strict=True))
        paths[0] = self.paths[0].split("/")[0]
        for b in range(m.nbody):
            geoms = np.flatnonzero(m.geom_bodyid == b)
            kinds = m.geom_type[geoms]
            box = geoms[kinds == mujoco.mjtGeom.mjGEOM_BOX]
            cap = geoms[kinds == mujoco.mjtGeom.mjGEOM_CAPSULE]
            plane = geoms[kinds == mujoco.mjtGeom.mjGEOM_PLANE]  # other shapes are not in the HRP-2 model
            if len(box):
                rec.log(f"{paths[b]}/boxes", rr.Boxes3D(centers=m.geom_pos[box], half_sizes=m.geom_size[box],
                                                        quaternions=m.geom_quat[box][:, [1, 2, 3, 0]],
                                                        colors=[COLOR]), static=True)
            if len(cap):
                half = m.geom_size[cap, 1]
                axis = np.empty((len(cap), 3))
                for i, g in enumerate(cap):
                    mujoco.mju_rotVecQuat(axis[i], np.array([0.0, 0.0, 1.0]), m.geom_quat[g])
                rec.log(f"{paths[b]}/capsules", rr.Capsules3D(
                    lengths=2 * half, radii=m.geom_size[cap, 0], translations=m.geom_pos[cap] - axis * half[:, None],
                    quaternions=m.geom_quat[cap][:, [1, 2, 3, 0]], colors=[COLOR]), static=True)
            if len(plane):
                rec.log(f"{paths[b]}/floor", rr.Boxes3D(centers=[[0, 0, -0.005]], half_sizes=[[1.0, 1.0, 0.005]],
                                                        colors=[[200, 200, 200, 80]]), static=True)

    def transforms(self, q: np.ndarray, base_position=None, base_quat_wxyz=None) -> tuple[np.ndarray, np.ndarray]:
        """Per body (in :attr:`paths` order): translation (nb, 3) [m] and quaternion xyzw (nb, 4) relative to
        the parent body, at joint angles ``q`` [rad] and the base pose (default: the model's, 0.75 m high)."""
        m, d = self.model, self.data
        d.qpos[:] = m.qpos0
        if self._free:
            d.qpos[2] = 0.75
            if base_position is not None:
                d.qpos[0:3] = base_position
            if base_quat_wxyz is not None:
                d.qpos[3:7] = base_quat_wxyz
        d.qpos[self._qadr] = q
        mujoco.mj_kinematics(m, d)
        pos, quat = d.xpos[self.bodies], d.xquat[self.bodies]
        ppos, pquat = d.xpos[self.parents], d.xquat[self.parents]
        nb = len(self.bodies)
        rel_t, rel_q = np.empty((nb, 3)), np.empty((nb, 4))
        inv = np.empty(4)
        for i in range(nb):
            mujoco.mju_negQuat(inv, pquat[i])
            mujoco.mju_rotVecQuat(rel_t[i], pos[i] - ppos[i], inv)
            mujoco.mju_mulQuat(rel_q[i], inv, quat[i])
        return rel_t, rel_q[:, [1, 2, 3, 0]]
