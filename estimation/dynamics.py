"""One tick of the paper's Algorithm 1 after filtering: IMU -> base, F/T compensation, RNEA, eq. 2.

Given filtered joint angles, velocities and accelerations, the IMU's angular velocity (and its
derivative) and specific force, and the offset-free F/T wrenches, :meth:`InverseDynamics.compute`
fills preallocated arrays with:

1. Base (waist) kinematics from the chest IMU (section 2.3, footnote 1). With the base placed at
   the identity and a zero linear velocity (Galilean invariance: the base's linear velocity
   changes no torque), the chest rate is ``R_bi w_imu = w_b + w_rel`` and the accelerometer reads
   ``f_imu = R_ib (a_b - g) + R_ib (alpha_b x r_bi) + c0``, where ``w_rel`` (chest joints) and ``c0``
   (the IMU's classical acceleration with zero base linear and angular acceleration) come from
   forward kinematics. Hence ``w_b``, ``alpha_b = R_bi (dw_imu - alpha_0)`` (or 0, "neglect") and
   the base proper acceleration ``a_b - g``.
2. End-effector wrenches (section 2.2): the measured wrench ``f_meas`` (what the distal side
   exerts on the proximal side) plus the inertial wrench of the bodies beyond the sensor,
   ``I (a - g) + v x* I v``, is the external wrench the environment exerts on the end effector,
   in the sensor frame at its origin. A first RNEA pass (model gravity 0, base velocity
   ``[0, w_b]``, base acceleration ``[a_b - g, alpha_b]``, no external force) gives that inertial
   wrench as the force transmitted by each sensor's locked joint (see :mod:`.model`).
3. Joint torques by a second RNEA pass with the external wrenches applied to the end effectors
   (section 2.3): the force transmitted through each sensor is then exactly the measured one.
4. The unknown external wrench (section 2.4, eq. 2): the 6 base rows of the RNEA output are the
   wrench the rest of the world must exert on the robot; it is assigned to one body (the torso by
   default) and the torques of the joints between the base and that body are corrected, which is
   the exact least-squares solution of eq. 2 (the problem is square).

No NaN ever enters: the caller (the estimator) holds the last valid inputs and flags the outputs.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from servotau.errors import EstimationError

from .model import EstimatorModel


def _index_or_slice(idx: np.ndarray):
    """A slice if ``idx`` is a contiguous increasing range (views, no gather), else the array."""
    if idx.size and np.all(np.diff(idx) == 1):
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx


def cross_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out = a x b`` for 3-vectors without a temporary array (``np.cross`` allocates and is slow)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    out[0] = a1 * b2 - a2 * b1
    out[1] = a2 * b0 - a0 * b2
    out[2] = a0 * b1 - a1 * b0
    return out


class InverseDynamics:
    """Preallocated per-tick torque computation (shared by the on-line and off-line estimators).

    Output attributes (arrays overwritten in place by every :meth:`compute`):
        tau: [N m] (n,) joint torques, HAL joint order.
        base_wrench: [N, N m] (6,) unknown external wrench on ``unknown_wrench_link``, in that body's
            frame at its origin (force then torque).
        wrenches: [N, N m] (n_ft, 6) external wrench on each end effector, sensor frame and origin.
        beyond_wrench: [N, N m] (n_ft, 6) inertial wrench (gravity included) of the bodies beyond each
            sensor, sensor frame: ``wrenches = measured + beyond_wrench``.
        base_angular_velocity: [rad/s] (3,) waist, waist frame.
        base_angular_acceleration: [rad/s^2] (3,) waist, waist frame.
        base_specific_force: [m/s^2] (3,) ``a_b - g`` of the waist origin, waist frame.

    On demand (calibration): :meth:`ft_motion`, :meth:`ft_specific_force`, :meth:`distal_joint_wrench`.
    """

    def __init__(self, robot: EstimatorModel, angular_acceleration: str = "savgol"):
        self.robot = robot
        m = robot.model
        self.model = m
        self.data = m.createData()  # once, never per tick
        self.use_alpha = angular_acceleration == "savgol"
        n, nft = robot.n, len(robot.ft)
        self._jq = _index_or_slice(robot.joints.idx_q)
        self._jv = _index_or_slice(robot.joints.idx_v)
        self._q = pin.neutral(m)
        self._v = np.zeros(m.nv)
        self._a = np.zeros(m.nv)
        self._fext = pin.StdVec_Force()
        for _ in range(m.njoints):
            self._fext.append(pin.Force.Zero())
        d = self.data
        jc = robot.imu_joint
        imu = m.frames[robot.imu_frame].placement
        self._R_ci = np.array(imu.rotation)
        self._p_ci = np.array(imu.translation)
        # Views into pin.Data, refreshed in place by every forward pass (Data is never reallocated).
        self._R_bc = d.oMi[jc].rotation
        self._p_bc = d.oMi[jc].translation
        self._w_rel = d.v[jc].np[3:6]
        self._tau_all = d.tau
        self._sensors = []
        for s, geo in enumerate(robot.ft):
            lj = geo.joint_id
            sensor_X_joint = np.array(geo.joint_M_sensor.inverse().toDualActionMatrix())  # forces joint -> sensor
            joint_X_sensor = np.array(geo.joint_M_sensor.toDualActionMatrix())  # forces sensor -> joint
            self._sensors.append([s, d.f[lj].np, sensor_X_joint, joint_X_sensor, self._fext[lj].np, None, None])
        self._path = [(robot.joints.joint_ids.tolist().index(j), j, axis)
                      for j, axis in zip(robot.unknown_path, robot.unknown_path_axes, strict=True)]
        self._L = robot.unknown_joint
        # Outputs and scratch.
        self.tau = np.zeros(n)
        self.base_wrench = np.zeros(6)
        self.wrenches = np.zeros((nft, 6))
        self.beyond_wrench = np.zeros((nft, 6))
        self.base_angular_velocity = np.zeros(3)
        self.base_angular_acceleration = np.zeros(3)
        self.base_specific_force = np.zeros(3)
        self._t3 = np.zeros(3)
        self._u3 = np.zeros(3)
        self._r3 = np.zeros(3)
        self._R_bi = np.zeros((3, 3))
        self.bind_outputs()

    def bind_outputs(self, **arrays: np.ndarray) -> None:
        """Write the outputs named in ``arrays`` (see the class docstring) into the given arrays from now on
        (e.g. a caller's preallocated holder), instead of copying them out every tick."""
        for name, arr in arrays.items():
            old = getattr(self, name)
            if not isinstance(arr, np.ndarray) or arr.shape != old.shape or arr.dtype != np.float64:
                raise EstimationError(f"bind_outputs: {name} must be a float64 array of shape {old.shape}")
            setattr(self, name, arr)
        for entry in self._sensors:  # row views of the outputs, per sensor
            entry[5], entry[6] = self.wrenches[entry[0]], self.beyond_wrench[entry[0]]

    def compute(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, gyro: np.ndarray, dgyro: np.ndarray,
                accel: np.ndarray, wrenches: np.ndarray) -> None:
        """One tick from filtered, finite inputs (see the class docstring for the outputs).

        Args:
            q, dq, ddq: [rad, rad/s, rad/s^2] (n,) HAL joint order.
            gyro: [rad/s] (3,) chest angular velocity, IMU frame (bias removed).
            dgyro: [rad/s^2] (3,) its time derivative (unused with ``angular_acceleration="neglect"``).
            accel: [m/s^2] (3,) accelerometer specific force, IMU frame.
            wrenches: [N, N m] (n_ft, 6) measured F/T wrenches (HAL convention), offsets removed.
        """
        m, d = self.model, self.data
        qp, vp, ap = self._q, self._v, self._a
        qp[self._jq] = q
        vp[self._jv] = dq
        ap[self._jv] = ddq
        vp[:6] = 0.0
        ap[:6] = 0.0
        # 1. Base angular velocity: chest rate minus the chest joints' contribution.
        pin.forwardKinematics(m, d, qp, vp)
        t3, u3, r3, R_bi = self._t3, self._u3, self._r3, self._R_bi
        np.dot(self._R_ci, gyro, out=t3)
        t3 -= self._w_rel
        w_b = self.base_angular_velocity
        np.dot(self._R_bc, t3, out=w_b)
        vp[3:6] = w_b
        # Base angular and linear (proper) acceleration from the IMU.
        pin.forwardKinematics(m, d, qp, vp, ap)
        imu_acc = pin.getFrameClassicalAcceleration(m, d, self.robot.imu_frame, pin.LOCAL)
        acc0 = imu_acc.np  # a view: imu_acc must stay alive while it is read
        np.dot(self._R_bc, self._R_ci, out=R_bi)
        alpha_b = self.base_angular_acceleration
        if self.use_alpha:
            np.subtract(dgyro, acc0[3:6], out=t3)
            np.dot(R_bi, t3, out=alpha_b)
        else:
            alpha_b.fill(0.0)
        np.subtract(accel, acc0[0:3], out=t3)
        a_b = self.base_specific_force
        np.dot(R_bi, t3, out=a_b)
        if self.use_alpha:
            np.dot(self._R_bc, self._p_ci, out=r3)
            r3 += self._p_bc
            a_b -= cross_into(alpha_b, r3, u3)
        ap[0:3] = a_b
        ap[3:6] = alpha_b
        # 2. End-effector wrenches: measured + inertial wrench of the bodies beyond each sensor, which the
        # first RNEA pass (no external force) returns as the force of the sensor's locked joint.
        pin.rnea(m, d, qp, vp, ap)
        for s, f_beyond, s_X_j, j_X_s, fext_j, ext_s, beyond_s in self._sensors:
            np.dot(s_X_j, f_beyond, out=beyond_s)
            np.add(wrenches[s], beyond_s, out=ext_s)
            np.dot(j_X_s, ext_s, out=fext_j)
        # 3. RNEA with the external wrenches.
        pin.rnea(m, d, qp, vp, ap, self._fext)
        tau_all = self._tau_all
        np.take(tau_all, self.robot.joints.idx_v, out=self.tau)
        # 4. Unknown wrench on the chosen body (base rows of the RNEA output), path torques corrected.
        f_b = pin.Force(tau_all[0:6])
        f_L = d.oMi[self._L].actInv(f_b)
        np.copyto(self.base_wrench, f_L.vector)
        for i, j, axis in self._path:
            f_j = d.oMi[j].actInv(f_b)
            self.tau[i] -= float(np.dot(axis, f_j.vector))

    def distal_joint_wrench(self, out: np.ndarray | None = None) -> np.ndarray:
        """[N, N m] (n_ft, 6) the part of :attr:`beyond_wrench` due to the bodies behind an actuated joint
        beyond each sensor (the gripper), sensor frame, at the state of the last :meth:`compute`."""
        out = np.zeros((len(self.robot.ft), 6)) if out is None else out
        m, d = self.model, self.data
        for s, geo in enumerate(self.robot.ft):
            total = pin.Force.Zero()
            for k in geo.distal_joints:
                if m.parents[k] == geo.joint_id:  # its force includes its own subtree
                    total += d.liMi[k].act(d.f[k])
            out[s] = geo.joint_M_sensor.actInv(total).vector
        return out

    def ft_motion(self, velocity: np.ndarray, acceleration: np.ndarray) -> None:
        """Spatial velocity and acceleration (gravity folded in: ``a - g``) of each F/T sensor frame, in
        that frame, at the state of the last :meth:`compute`; written into (n_ft, 6) arrays."""
        d = self.data
        for s, geo in enumerate(self.robot.ft):
            v = geo.joint_M_sensor.actInv(d.v[geo.joint_id])
            a = geo.joint_M_sensor.actInv(d.a_gf[geo.joint_id])  # the RNEA's accelerations (model gravity is 0)
            velocity[s] = v.vector
            acceleration[s] = a.vector

    def ft_specific_force(self, out: np.ndarray | None = None) -> np.ndarray:
        """[m/s^2] (n_ft, 3) classical acceleration minus gravity of each F/T sensor origin, in its frame
        (what an accelerometer there would read), at the state of the last :meth:`compute`."""
        n_ft = len(self.robot.ft)
        out = np.zeros((n_ft, 3)) if out is None else out
        v, a = np.zeros((n_ft, 6)), np.zeros((n_ft, 6))
        self.ft_motion(v, a)
        for s in range(n_ft):
            out[s] = a[s, :3] + np.cross(v[s, 3:], v[s, :3])
        return out
