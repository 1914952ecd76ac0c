"""Joint-space rigid-body dynamics of the controller's robot model (Pinocchio), fixed or floating base.

- ``base="fixed"`` (the paper, footnote 3: the robot hangs from a lift, its base barely moves): the free
  flyer is locked upright at the origin with :func:`pinocchio.buildReducedModel`; the model has the
  30 actuated joints only.
- ``base="floating"``: the full model, written in the base (waist) frame: the base is placed at the origin
  with identity orientation and zero linear velocity, gravity is set to 0 and the base's linear acceleration
  is its specific force (acceleration minus gravity, as an accelerometer reads it). The estimator gives
  the base's angular velocity, angular acceleration and specific force in the waist frame; that is all
  the joint rows of ``M a + h`` depend on.

Joint rows of ``M a + h`` come from one RNEA call (``rnea(q, v, a)`` with ``a = [a_base, ddq]``), which is
cheaper than forming ``M``. One ``pin.Data`` is allocated at construction and reused on every tick.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from servotau.description import ROOT_JOINT, load_pinocchio
from servotau.errors import ControlError

from .config import BASES


class BaseState(NamedTuple):
    """Motion of the base (waist) in its own frame, as the estimator gives it."""

    angular_velocity: np.ndarray  # [rad/s] (3,)
    angular_acceleration: np.ndarray  # [rad/s^2] (3,)
    specific_force: np.ndarray  # [m/s^2] (3,) acceleration minus gravity (reads [0, 0, 9.81] at rest, upright)


def _as_index(idx: np.ndarray) -> slice | np.ndarray:
    """A slice when ``idx`` is contiguous and increasing (cheaper views), else the index array."""
    if idx.size and np.all(np.diff(idx) == 1):
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx


class RobotDynamics:
    """``M(q) a + h(q, v)`` on the actuated joints, frame Jacobians and wrench transforms."""

    def __init__(self, model_path: str | Path, joint_names: Sequence[str], base: str = "fixed",
                 root_joint: str = ROOT_JOINT):
        """``root_joint``: the model's free flyer (:attr:`RobotInfo.root_joint`)."""
        if base not in BASES:
            raise ControlError(f"base = {base!r}: expected one of {list(BASES)}")
        full = load_pinocchio(model_path, root_joint)
        self.base = base
        if base == "fixed":
            model = pin.buildReducedModel(full, [full.getJointId(root_joint)], pin.neutral(full))
        else:
            model = full
            self.gravity = np.array(full.gravity.linear)  # [m/s^2] world gravity, for fixed-base comparisons
            model.gravity.linear = np.zeros(3)  # gravity enters through the base's specific force
        self.joint_names = tuple(joint_names)
        q_idx, v_idx = [], []
        for name in self.joint_names:
            if not model.existJointName(name):
                raise ControlError(f'joint "{name}" is not in the robot model {model_path}: expected one of '
                                   f"{list(model.names)[1:]}")
            jid = model.getJointId(name)
            if model.nqs[jid] != 1 or model.nvs[jid] != 1:
                raise ControlError(f'joint "{name}": expected a 1-dof joint in {model_path}')
            q_idx.append(model.idx_qs[jid])
            v_idx.append(model.idx_vs[jid])
        n_base = 0 if base == "fixed" else 6
        if model.nv != len(self.joint_names) + n_base:
            raise ControlError(f"the robot model has {model.nv - n_base} joints: expected {len(self.joint_names)} "
                               f"({list(self.joint_names)})")
        self.model = model
        self._q_idx = _as_index(np.array(q_idx))
        self._v_idx = _as_index(np.array(v_idx))
        self._q = pin.neutral(model)
        self._v = np.zeros(model.nv)
        self._a = np.zeros(model.nv)
        self.data = model.createData()

    @property
    def n(self) -> int:
        """Number of actuated joints."""
        return len(self.joint_names)

    # -- frames, built before the first tick -----------------------------------------------------
    def frame_id(self, name: str) -> int:
        """Index of frame ``name`` of the model."""
        if not self.model.existFrame(name):
            raise ControlError(f'frame "{name}" is not a frame of the robot model: expected one of '
                               f"{[f.name for f in self.model.frames]}")
        return self.model.getFrameId(name)

    def add_offset_frame(self, name: str, parent: str, offset: Sequence[float]) -> int:
        """Add frame ``name`` at ``offset`` [m] from frame ``parent`` (same orientation); return its index.

        The model's ``Data`` is rebuilt: call before the first tick only.
        """
        if self.model.existFrame(name):
            raise ControlError(f'frame "{name}" already exists: expected a new frame name')
        pid = self.frame_id(parent)
        pf = self.model.frames[pid]
        placement = pf.placement * pin.SE3(np.eye(3), np.asarray(offset, dtype=float))
        fid = self.model.addFrame(pin.Frame(name, pf.parentJoint, pid, placement, pin.FrameType.OP_FRAME))
        self.data = self.model.createData()
        return fid

    def wrench_transform(self, from_frame: int, to_frame: int) -> np.ndarray:
        """(6, 6) map of a wrench ``[f, tau]`` at ``from_frame`` to the same wrench at ``to_frame``.

        Both frames must be on the same body (a constant transform).
        """
        a, b = self.model.frames[from_frame], self.model.frames[to_frame]
        if a.parentJoint != b.parentJoint:
            raise ControlError(f'frames "{a.name}" and "{b.name}" are on different bodies: expected the F/T sensor '
                               "and the force-task frame on the same body")
        to_M_from = b.placement.inverse() * a.placement
        return np.array(to_M_from.toDualActionMatrix())

    # -- per tick ----------------------------------------------------------------------------------
    def set_state(self, q: np.ndarray, dq: np.ndarray, base: BaseState | None = None) -> None:
        """Joint angles [rad] and velocities [rad/s]; with a floating base also the base state (required)."""
        self._q[self._q_idx] = q
        self._v[self._v_idx] = dq
        if self.base == "floating":
            if base is None:
                raise ControlError("base is None: expected the base state (angular velocity, angular acceleration, "
                                   "specific force) with a floating base")
            self._v[3:6] = base.angular_velocity
            self._a[0:3] = base.specific_force
            self._a[3:6] = base.angular_acceleration

    def inverse_dynamics(self, ddq: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``out = (M a + h)`` on the joint rows [N m] for joint accelerations ``ddq`` [rad/s^2] (and the base's
        acceleration of :meth:`set_state`)."""
        self._a[self._v_idx] = ddq
        tau = pin.rnea(self.model, self.data, self._q, self._v, self._a)
        out[:] = tau[self._v_idx]
        return out

    def jacobian(self, frame: int, out: np.ndarray) -> np.ndarray:
        """``out`` (6, n): the frame's Jacobian on the joints, LOCAL (in the frame, at its origin)."""
        jac = pin.computeFrameJacobian(self.model, self.data, self._q, frame, pin.LOCAL)
        out[:] = jac[:, self._v_idx]
        return out

    # -- not per tick ------------------------------------------------------------------------------
    def mass_matrix(self) -> np.ndarray:
        """(n, n) joint block ``M_j`` of the mass matrix [kg m^2] at the state of :meth:`set_state`."""
        m = pin.crba(self.model, self.data, self._q)
        m = np.triu(m) + np.triu(m, 1).T
        return m[self._v_idx][:, self._v_idx].copy()
