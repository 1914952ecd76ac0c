"""The estimator's rigid-body model: Pinocchio model, joints addressed by name, sensor geometry.

Built from :attr:`RobotInfo.model_path` (the MJCF file) by :func:`servotau.description.load_pinocchio`,
the F/T sensors at :attr:`RobotInfo.ft_sensor_frames`: nothing from the simulator. The model's gravity
is set to zero: the estimator feeds the measured proper acceleration of the base (``a_b - g``, from the
IMU) as the base acceleration instead.

Conventions:
- Pinocchio's base is the waist ``BODY`` (the free flyer ``root``); the estimator always places it
  at the identity, so "world" quantities of Pinocchio (``oMi``, ``oMf``) are in the base frame.
- Welded bodies (the feet, the hands) are frames whose ``inertia`` holds their own inertia, while
  the parent joint's inertia includes them. The body *beyond* an F/T sensor is the welded body
  carrying the sensor's site plus every body below it (the gripper beyond the wrist sensor).
- :func:`split_sensor_bodies` gives each such welded body its own joint, locked at zero (a revolute
  joint whose q, v and a the estimator keeps at 0): kinematics and dynamics are unchanged, but the RNEA
  now returns the inertial wrench of everything beyond each sensor (``data.f`` of that joint), computed
  in C++ instead of per tick in Python.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from servotau.description import load_pinocchio
from servotau.errors import EstimationError
from servotau.hal.types import RobotInfo

from .config import EstimatorConfig, ModelPerturbation


@dataclass(frozen=True)
class JointAddress:
    """Where each HAL joint (``RobotInfo.joint_names`` order) lives in Pinocchio's q and v."""

    names: tuple[str, ...]
    joint_ids: np.ndarray  # (n,) Pinocchio joint ids
    idx_q: np.ndarray  # (n,) index in q
    idx_v: np.ndarray  # (n,) index in v

    @classmethod
    def by_name(cls, model: pin.Model, names: tuple[str, ...], locked: tuple[int, ...] = ()) -> JointAddress:
        """Match HAL joint names to the model's joints; every model joint but the ``locked`` ones (added
        by :func:`split_sensor_bodies`) must be named once."""
        ids, iq, iv = [], [], []
        for name in names:
            if not model.existJointName(name) or model.getJointId(name) in locked:
                movable = [model.names[j] for j in range(2, model.njoints) if j not in locked]
                raise EstimationError(
                    f"joint \"{name}\" is not a joint of the estimator model: expected one of {movable}"
                )
            j = model.getJointId(name)
            if model.nqs[j] != 1 or model.nvs[j] != 1:
                raise EstimationError(f'joint "{name}": expected a 1-dof joint, got nq={model.nqs[j]}')
            ids.append(j)
            iq.append(model.idx_qs[j])
            iv.append(model.idx_vs[j])
        missing = [model.names[j] for j in range(2, model.njoints) if j not in ids and j not in locked]
        if missing:
            raise EstimationError(f"model joints {missing} are not in RobotInfo.joint_names: expected every joint")
        arrays = [np.array(a, dtype=np.intp) for a in (ids, iq, iv)]
        for a in arrays:
            a.setflags(write=False)
        return cls(tuple(names), *arrays)


@dataclass(frozen=True)
class FtSensorGeometry:
    """One F/T sensor of the split model: where it is and which bodies lie beyond it."""

    name: str  # HAL sensor name
    frame_id: int  # model frame of the sensor
    joint_id: int  # locked joint whose body is the welded body beyond the sensor
    parent_joint: int  # the actuated joint carrying it (e.g. the ankle roll)
    joint_M_sensor: pin.SE3  # sensor placement in the locked joint's frame
    welded_inertia: pin.Inertia  # the welded bodies beyond the sensor, locked joint frame
    distal_joints: tuple[int, ...]  # actuated joints beyond the sensor (the gripper), with their subtrees


def _welded_frames(model: pin.Model, joint: int) -> list[int]:
    return [
        f for f, fr in enumerate(model.frames)
        if fr.type == pin.FrameType.FIXED_JOINT and fr.parentJoint == joint and fr.inertia.mass > 0.0
    ]


def perturb_inertias(model: pin.Model, perturbation: ModelPerturbation) -> pin.Model:
    """A copy of ``model`` whose body masses, rotational inertias and CoMs are randomly perturbed.

    Joint bodies and welded bodies are perturbed separately, then recombined, so that the welded
    frames' inertias (used to compensate the F/T sensors) stay consistent with the joints'.
    """
    out = model.copy()
    if not perturbation.enabled:
        return out
    rng = np.random.default_rng(perturbation.seed)

    def draw(inertia: pin.Inertia) -> pin.Inertia:
        scale = float(np.clip(1.0 + perturbation.mass_scale_std * rng.standard_normal(), 0.5, 1.5))
        com = inertia.lever + perturbation.com_offset_std * rng.standard_normal(3)
        return pin.Inertia(inertia.mass * scale, com, inertia.inertia * scale)

    for j in range(1, out.njoints):
        welded = _welded_frames(out, j)
        own = out.inertias[j].copy()
        for f in welded:
            own = own - out.frames[f].placement.act(out.frames[f].inertia)
        total = draw(own)
        for f in welded:
            frame = out.frames[f]
            frame.inertia = draw(frame.inertia)
            out.frames[f] = frame
            total = total + frame.placement.act(frame.inertia)
        out.inertias[j] = total
    return out


def _frame_descendants(model: pin.Model, root_frame: int) -> list[int]:
    """Frames whose chain of parent frames passes through ``root_frame`` (included)."""
    out = []
    for f in range(model.nframes):
        g = f
        while True:
            if g == root_frame:
                out.append(f)
                break
            parent = model.frames[g].parentFrame
            if parent == g or g == 0:
                break
            g = parent
    return out


def _sensor_body(model: pin.Model, sensor: str, frame_name: str) -> tuple[int, int]:
    """(body frame carrying the sensor site, FIXED_JOINT frame of that welded body)."""
    if not model.existFrame(frame_name):
        raise EstimationError(f'F/T sensor "{sensor}": the model has no frame "{frame_name}"')
    fid = model.getFrameId(frame_name)
    frame = model.frames[fid]
    body = frame.parentFrame if frame.type == pin.FrameType.OP_FRAME else fid
    welded = model.frames[body].parentFrame
    if model.frames[body].type != pin.FrameType.BODY or model.frames[welded].type != pin.FrameType.FIXED_JOINT:
        raise EstimationError(
            f'F/T sensor "{sensor}": frame "{frame_name}" must be on a welded body (a body without a joint) '
            "so that the body beyond the sensor is defined"
        )
    return body, welded


def split_sensor_bodies(model: pin.Model, frames: dict[str, str]) -> tuple[pin.Model, dict[str, int]]:
    """A copy of ``model`` where the welded body carrying each F/T sensor hangs from its own locked joint.

    Args:
        model: The robot model (welded bodies as frames).
        frames: HAL sensor name -> model frame of the sensor site.

    Returns:
        ``(split, locked)``: the new model (same joint names, one extra revolute joint ``<body>_ft`` per
        sensor, to be kept at q = v = a = 0) and the locked joint id of each sensor.
    """
    owner: dict[int, int] = {}  # frame on a split welded body -> its FIXED_JOINT frame
    by_sensor: dict[str, int] = {}
    for sensor, frame_name in frames.items():
        body, welded = _sensor_body(model, sensor, frame_name)
        j = model.frames[welded].parentJoint
        for f in [welded, *_frame_descendants(model, body)]:
            if model.frames[f].parentJoint == j:
                owner[f] = welded
        by_sensor[sensor] = welded
    if len(set(by_sensor.values())) < len(by_sensor):
        raise EstimationError(f"F/T sensors {sorted(by_sensor)} share a welded body: expected one per body")
    out = pin.Model()
    out.name = model.name
    jmap, locked_of = {0: 0}, {}
    joint_frame = {model.frames[f].parentJoint: f for f in range(model.nframes)
                   if model.frames[f].type == pin.FrameType.JOINT}
    for j in range(1, model.njoints):
        parent_frame = model.frames[joint_frame[j]].parentFrame if j in joint_frame else None
        if parent_frame in owner:  # a joint beyond a sensor: re-attach it to the locked joint
            w = owner[parent_frame]
            parent, placement = locked_of[w], model.frames[w].placement.inverse() * model.jointPlacements[j]
        else:
            parent, placement = jmap[model.parents[j]], model.jointPlacements[j]
        nj = out.addJoint(parent, model.joints[j], placement, model.names[j])
        jmap[j] = nj
        inertia = model.inertias[j].copy()
        splits = sorted({w for w in owner.values() if model.frames[w].parentJoint == j})
        for w in splits:
            for f in (g for g, o in owner.items() if o == w and model.frames[g].type == pin.FrameType.FIXED_JOINT):
                inertia = inertia - model.frames[f].placement.act(model.frames[f].inertia)
        out.appendBodyToJoint(nj, inertia, pin.SE3.Identity())
        for w in splits:
            wMo = model.frames[w].placement.inverse()
            lj = out.addJoint(nj, pin.JointModelRX(), model.frames[w].placement, f"{model.frames[w].name}_ft")
            body_inertia = pin.Inertia.Zero()
            for f in (g for g, o in owner.items() if o == w and model.frames[g].type == pin.FrameType.FIXED_JOINT):
                body_inertia = body_inertia + (wMo * model.frames[f].placement).act(model.frames[f].inertia)
            out.appendBodyToJoint(lj, body_inertia, pin.SE3.Identity())
            locked_of[w] = lj
    for j in range(1, model.njoints):
        nv, new, old = model.nvs[j], out.idx_vs[jmap[j]], model.idx_vs[j]
        out.armature[new : new + nv] = model.armature[old : old + nv]
    fmap = {0: 0}
    for f in range(1, model.nframes):
        fr = model.frames[f]
        if f in owner:
            w = owner[f]
            joint, placement = locked_of[w], model.frames[w].placement.inverse() * fr.placement
        else:
            joint, placement = jmap[fr.parentJoint], fr.placement
        fmap[f] = out.addFrame(pin.Frame(fr.name, joint, fmap[fr.parentFrame], placement, fr.type), False)
    out.gravity = model.gravity
    return out, {s: locked_of[w] for s, w in by_sensor.items()}


def ft_sensor_geometry(model: pin.Model, sensor: str, frame_name: str, locked: int) -> FtSensorGeometry:
    """Geometry of the F/T sensor ``sensor`` (site frame ``frame_name``) in a split model."""
    fid = model.getFrameId(frame_name)
    frame = model.frames[fid]
    if frame.parentJoint != locked:
        raise EstimationError(f'F/T sensor "{sensor}": frame "{frame_name}" is not on its locked joint')
    distal = tuple(int(k) for k in model.subtrees[locked] if k != locked)
    return FtSensorGeometry(
        name=sensor, frame_id=fid, joint_id=locked, parent_joint=int(model.parents[locked]),
        joint_M_sensor=frame.placement.copy(), welded_inertia=model.inertias[locked].copy(), distal_joints=distal,
    )


class EstimatorModel:
    """The Pinocchio model of the estimator with everything resolved by name at construction.

    Attributes:
        model: Pinocchio model, gravity zero (the IMU supplies it), armature as configured, the bodies
            beyond the F/T sensors split onto locked joints (:func:`split_sensor_bodies`).
        locked_joints: The locked joints, one per F/T sensor (q = v = a = 0 always).
        joints: HAL joint order -> Pinocchio indices.
        ft: One :class:`FtSensorGeometry` per HAL F/T sensor, in ``RobotInfo.ft_sensor_names`` order.
        imu_frame, imu_joint: IMU frame and the joint carrying it.
        unknown_joint: Joint of the body that takes the unknown external wrench.
        unknown_path: Joints between the base and that body (their torques are corrected).
        unknown_path_axes: (len(path), 6) motion subspace of each path joint, in its own frame.
    """

    def __init__(self, info: RobotInfo, config: EstimatorConfig):
        frames = {s: info.ft_frame(s) for s in info.ft_sensor_names}
        full = load_pinocchio(info.model_path, info.root_joint)
        model, locked = split_sensor_bodies(perturb_inertias(full, config.perturbation), frames)
        model.gravity = pin.Motion.Zero()
        if not config.armature:
            model.armature[:] = 0.0
        self.model = model
        self.info = info
        self.locked_joints = tuple(locked[s] for s in info.ft_sensor_names)
        self.joints = JointAddress.by_name(model, tuple(info.joint_names), self.locked_joints)
        self.ft = tuple(ft_sensor_geometry(model, s, frames[s], locked[s]) for s in info.ft_sensor_names)
        if not model.existFrame(config.imu_frame):
            raise EstimationError(f'IMU: the model has no frame "{config.imu_frame}"')
        self.imu_frame = model.getFrameId(config.imu_frame)
        self.imu_joint = int(model.frames[self.imu_frame].parentJoint)
        link = config.unknown_wrench_link
        if not model.existFrame(link, pin.BODY):
            bodies = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
            raise EstimationError(f'unknown_wrench_link "{link}" is not a body of the model: expected one of {bodies}')
        self.unknown_joint = int(model.frames[model.getFrameId(link, pin.BODY)].parentJoint)
        self.unknown_path = tuple(int(j) for j in model.supports[self.unknown_joint] if j > 1)
        data = model.createData()
        pin.computeJointJacobians(model, data, pin.neutral(model))
        axes = [pin.getJointJacobian(model, data, j, pin.LOCAL)[:, model.idx_vs[j]] for j in self.unknown_path]
        self.unknown_path_axes = np.array(axes).reshape(len(self.unknown_path), 6)

    @property
    def n(self) -> int:
        return len(self.joints.names)

    def dependencies(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Which inputs each output depends on (conservatively), for the validity flags.

        Returns:
            ``(tau_on_encoders, tau_on_ft, wrench_on_encoders)``: bool arrays (n, n), (n, n_ft) and
            (n_ft, n). Row i of the first two says which encoders and F/T sensors joint i's torque uses;
            row s of the third which encoders the compensation of sensor s uses. All use the IMU.
        """
        m, jid = self.model, self.joints.joint_ids
        n, nft = self.n, len(self.ft)
        pos = {int(j): i for i, j in enumerate(jid)}
        imu_path = {int(j) for j in m.supports[self.imu_joint] if j > 1}
        enc = np.zeros((n, n), dtype=bool)
        ftd = np.zeros((n, nft), dtype=bool)
        for i, j in enumerate(jid):
            j = int(j)
            subtree = {int(k) for k in m.subtrees[j]}
            if j in self.unknown_path:  # computed from the base side: uses everything
                enc[i, :] = True
                ftd[i, :] = True
                continue
            used = subtree | {int(k) for k in m.supports[j] if k > 1} | imu_path
            for k in used & pos.keys():
                enc[i, pos[k]] = True
            for s, geo in enumerate(self.ft):
                ftd[i, s] = geo.joint_id in subtree
        ft_enc = np.zeros((nft, n), dtype=bool)
        for s, geo in enumerate(self.ft):
            used = {int(k) for k in m.supports[geo.joint_id] if k > 1} | imu_path | set(geo.distal_joints)
            for k in used & pos.keys():
                ft_enc[s, pos[k]] = True
        return enc, ftd, ft_enc
