"""Inverse-dynamics control law of the paper (eq. 12): the desired joint torques.

::

    tau_d = M_j ddq_d + h - sum_c J_c^T f*_c + K_s e_q + K_d de_q       [N m]
    f*    = f_d + K_f e_f,  e_f = f_d - f_hat                          (force task, regulated axes)
    e_q = q_d - q_hat,  de_q = dq_d - dq_hat,  dde_q = ddq_d - ddq_hat

Contacts ``c`` are F/T sensors whose wrench acts on the robot. On the axes the force task regulates,
``f*`` is as above; on every other axis of a contact, the measured wrench ``f_hat`` enters as a
feedforward (``f* = f_hat``: the wrench is compensated, not regulated). Wrenches follow the HAL convention
(distal side on proximal side, which for a foot or hand is the environment's wrench on the robot plus the
compensated inertia of the hand or foot), expressed at the frame where ``J`` is taken.

Besides ``tau_d``, one call keeps the pieces that the paper's decomposition (eq. 13-14) needs:
``M ddq_d + h``, ``M ddq_hat + h``, the contact terms and the force-task terms.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from servotau.description import FT_FRAMES
from servotau.errors import ControlError
from servotau.hal.types import RobotInfo

from .config import ControlConfig, ForceTask
from .dynamics import BaseState, RobotDynamics

TASK_FRAME = "servotau_force_task"
"""Name of the frame added to the model when the force task has an offset."""


@dataclass
class _Contact:
    sensor: str
    row: int  # row in the HAL wrench array
    frame: int  # frame where J is taken
    transform: np.ndarray | None  # (6, 6) sensor frame -> ``frame``, None if the same
    jacobian: np.ndarray  # (6, n) buffer
    wrench: np.ndarray  # (6,) buffer: measured wrench at ``frame``


class InverseDynamics:
    """Eq. 12 for all joints, with a fixed or floating base, contacts and an optional force task."""

    def __init__(self, dynamics: RobotDynamics, k_s: np.ndarray, k_d: np.ndarray, contacts: tuple[str, ...] = (),
                 force: ForceTask | None = None, ft_frames: Mapping[str, str] = FT_FRAMES):
        """
        Args:
            dynamics: The robot model (its frames are extended here, so build it for this object).
            k_s: (n,) [N m/rad] stiffness per joint.
            k_d: (n,) [N m s/rad] damping per joint.
            contacts: F/T sensors (HAL names) whose measured wrenches are compensated.
            force: Force task, or None.
            ft_frames: HAL F/T sensor -> model frame of the sensor, in the row order of the HAL wrenches
                (:attr:`RobotInfo.ft_sensor_names` and ``ft_sensor_frames``).
        """
        self.dyn = dynamics
        n = dynamics.n
        self.k_s = _gain("k_s", k_s, n)
        self.k_d = _gain("k_d", k_d, n)
        sensors = list(contacts)
        if force is not None and force.sensor not in sensors:
            sensors.append(force.sensor)
        self._contacts: list[_Contact] = []
        self._task: _Contact | None = None
        ft_names = list(ft_frames)
        for s in sensors:
            if s not in ft_frames:
                raise ControlError(f"contact {s!r}: expected an F/T sensor among {ft_names}")
            sensor_frame = dynamics.frame_id(ft_frames[s])
            frame, transform = sensor_frame, None
            if force is not None and s == force.sensor:
                frame = dynamics.frame_id(force.frame)
                if any(force.offset):
                    frame = dynamics.add_offset_frame(TASK_FRAME, force.frame, force.offset)
                if frame != sensor_frame:
                    transform = dynamics.wrench_transform(sensor_frame, frame)
            c = _Contact(s, ft_names.index(s), frame, transform, np.zeros((6, n)), np.zeros(6))
            self._contacts.append(c)
            if force is not None and s == force.sensor:
                self._task = c
        self.force = force
        if force is not None:
            self._axes = force.axis_index
            self._free_axes = np.setdiff1d(np.arange(6), self._axes)
            self._k_f = np.array(force.k_f)
        # Outputs, refreshed in place by update().
        self.tau_d = np.zeros(n)  # [N m] eq. 12
        self.b_d = np.zeros(n)  # [N m] M ddq_d + h
        self.b_hat = np.zeros(n)  # [N m] M ddq_hat + h
        self.jtf_ff = np.zeros(n)  # [N m] sum_c J_c^T f_ff,c: f_d on regulated axes, f_hat elsewhere
        self.tau_ff = np.zeros(n)  # [N m] b_d - jtf_ff: the feedforward torque
        self.jtf_hat = np.zeros(n)  # [N m] sum_c J_c^T f_hat,c
        self.jt_ef = np.zeros(n)  # [N m] J_t^T e_f (regulated axes)
        self.jt_kf_ef = np.zeros(n)  # [N m] J_t^T K_f e_f
        self.e_q = np.zeros(n)  # [rad]
        self.de_q = np.zeros(n)  # [rad/s]
        self.dde_q = np.zeros(n)  # [rad/s^2]
        self.f_d = np.zeros(6)  # [N, N m] desired task wrench (only the regulated axes are used)
        self.f_hat = np.zeros(6)  # [N, N m] measured task wrench at the task frame
        self.e_f = np.zeros(6)  # [N, N m] f_d - f_hat on the regulated axes, 0 elsewhere
        self._f = np.zeros(6)
        self._f2 = np.zeros(6)  # K_f e_f, 0 on free axes
        self._tmp = np.zeros(n)

    @classmethod
    def from_config(cls, config: ControlConfig, model_path: str, info: RobotInfo | None = None) -> InverseDynamics:
        """Build the model and the law for ``config`` (gains of position-controlled joints are 0); ``info``
        gives the robot's root joint and F/T sensor frames (None: those of :mod:`servotau.description`)."""
        if info is None:
            dyn = RobotDynamics(model_path, config.joint_names, config.base)
            return cls(dyn, config.joint_vector("k_s"), config.joint_vector("k_d"), config.contacts, config.force)
        dyn = RobotDynamics(model_path, config.joint_names, config.base, info.root_joint)
        frames = dict(zip(info.ft_sensor_names, info.ft_sensor_frames, strict=True))
        return cls(dyn, config.joint_vector("k_s"), config.joint_vector("k_d"), config.contacts, config.force, frames)

    def set_gains(self, k_s: np.ndarray, k_d: np.ndarray) -> None:
        """Write the stiffness ``k_s`` [N m/rad] and damping ``k_d`` [N m s/rad] (n,) into the law's own arrays
        (in place: holders of :attr:`k_s` and :attr:`k_d` see the new values).

        Raises:
            ControlError: Not n finite numbers >= 0 (naming the gain).
        """
        n = self.dyn.n
        self.k_s[:] = _gain("k_s", k_s, n)
        self.k_d[:] = _gain("k_d", k_d, n)

    @property
    def contacts(self) -> tuple[str, ...]:
        return tuple(c.sensor for c in self._contacts)

    @property
    def task_jacobian(self) -> np.ndarray | None:
        """(k, n) Jacobian of the regulated axes at the last update (for K9), or None without a force task."""
        return None if self._task is None else self._task.jacobian[self._axes]

    def contact_jacobian(self, sensor: str) -> np.ndarray:
        """(6, n) Jacobian of contact ``sensor`` at the last update, at the frame where its wrench is expressed."""
        for c in self._contacts:
            if c.sensor == sensor:
                return c.jacobian
        raise ControlError(f"contact {sensor!r}: expected one of {list(self.contacts)}")

    def set_force_reference(self, f_d: np.ndarray) -> None:
        """Desired wrench ``[fx, fy, fz, tx, ty, tz]`` [N, N m] at the task frame (HAL sign convention)."""
        if self.force is None:
            raise ControlError("set_force_reference: no force task: expected a [force] table in the config")
        f_d = np.asarray(f_d, dtype=float)
        if f_d.shape != (6,) or not np.all(np.isfinite(f_d)):
            raise ControlError(f"f_d = {f_d!r}: expected 6 finite numbers [N, N m]")
        self.f_d[:] = f_d

    def update(self, q_hat, dq_hat, ddq_hat, q_d, dq_d, ddq_d, wrenches=None, base: BaseState | None = None
               ) -> np.ndarray:
        """Compute ``tau_d`` (n,) [N m] from the estimate and the reference (all (n,), RobotInfo order).

        Args:
            wrenches: (4, 6) compensated F/T wrenches in HAL order and convention; needed with contacts.
            base: Floating base only (see :class:`~servotau.control.dynamics.BaseState`).
        """
        dyn, tmp = self.dyn, self._tmp
        np.subtract(q_d, q_hat, out=self.e_q)
        np.subtract(dq_d, dq_hat, out=self.de_q)
        np.subtract(ddq_d, ddq_hat, out=self.dde_q)
        dyn.set_state(q_hat, dq_hat, base)
        dyn.inverse_dynamics(ddq_d, self.b_d)
        dyn.inverse_dynamics(ddq_hat, self.b_hat)
        tau_d = self.tau_d
        if self._contacts:
            if wrenches is None:
                raise ControlError(f"wrenches is None: expected (4, 6) F/T wrenches for contacts {self.contacts}")
            jtf_ff, jtf_hat = self.jtf_ff, self.jtf_hat
            for k, c in enumerate(self._contacts):
                dyn.jacobian(c.frame, c.jacobian)
                if c.transform is None:
                    c.wrench[:] = wrenches[c.row]
                else:
                    np.dot(c.transform, wrenches[c.row], out=c.wrench)
                if k == 0:
                    np.dot(c.wrench, c.jacobian, out=jtf_hat)  # J^T f_hat
                else:
                    np.dot(c.wrench, c.jacobian, out=tmp)
                    jtf_hat += tmp
                if c is self._task:
                    self._f[:] = c.wrench
                    self._f[self._axes] = self.f_d[self._axes]  # f_ff: f_d on regulated axes, f_hat elsewhere
                    np.dot(self._f, c.jacobian, out=jtf_ff)  # J_t^T f_ff (first term of jtf_ff)
                    self._task_terms(c)
            if self._task is None:
                np.copyto(jtf_ff, jtf_hat)
            elif len(self._contacts) > 1:  # the other contacts' measured wrenches
                for c in self._contacts:
                    if c is not self._task:
                        np.dot(c.wrench, c.jacobian, out=tmp)
                        jtf_ff += tmp
            np.subtract(self.b_d, jtf_ff, out=self.tau_ff)
            np.subtract(self.tau_ff, self.jt_kf_ef, out=tau_d)
        else:
            np.copyto(self.tau_ff, self.b_d)
            np.copyto(tau_d, self.b_d)
        np.multiply(self.k_s, self.e_q, out=tmp)
        tau_d += tmp
        np.multiply(self.k_d, self.de_q, out=tmp)
        tau_d += tmp
        return tau_d

    def _task_terms(self, t: _Contact) -> None:
        """Force-task errors and their joint torques ``J^T e_f``, ``J^T K_f e_f`` (regulated axes only)."""
        ax = self._axes
        self.f_hat[:] = t.wrench
        self.e_f[ax] = self.f_d[ax] - t.wrench[ax]
        np.dot(self.e_f, t.jacobian, out=self.jt_ef)
        f = self._f2
        f[ax] = self._k_f * self.e_f[ax]
        np.dot(f, t.jacobian, out=self.jt_kf_ef)


def _gain(name: str, value, n: int) -> np.ndarray:
    arr = np.array(value, dtype=float)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ControlError(f"{name} = {value!r}: expected {n} finite numbers >= 0")
    return arr
