"""Tests of the estimator's model (estimation/model.py): joints by name, sensor geometry, perturbation."""

import numpy as np
import pinocchio as pin
import pytest

from servotau.description import FT_FRAMES, JOINT_NAMES, MODEL_PATH, load_pinocchio
from servotau.errors import EstimationError
from servotau.estimation.config import EstimatorConfig, ModelPerturbation
from servotau.estimation.model import (
    EstimatorModel,
    JointAddress,
    perturb_inertias,
    split_sensor_bodies,
)
from servotau.hal.types import RobotInfo


def info_with(names) -> RobotInfo:
    n = len(names)
    return RobotInfo(name="test", joint_names=tuple(names), q_min=-np.ones(n), q_max=np.ones(n), period=1e-3,
                     model_path=str(MODEL_PATH))


def test_joints_are_addressed_by_name_in_any_order():
    """A shuffled HAL order maps each name to its own Pinocchio q and v index."""
    model = load_pinocchio(MODEL_PATH)
    names = list(JOINT_NAMES)
    np.random.default_rng(0).shuffle(names)
    address = JointAddress.by_name(model, tuple(names))
    for i, name in enumerate(names):
        j = model.getJointId(name)
        assert address.idx_q[i] == model.idx_qs[j] and address.idx_v[i] == model.idx_vs[j]


def test_unknown_or_missing_joint_names_raise():
    """A name absent from the model, or a model joint absent from the names, raises EstimationError."""
    model = load_pinocchio(MODEL_PATH)
    with pytest.raises(EstimationError, match="RLEG_JOINT9"):
        JointAddress.by_name(model, (*JOINT_NAMES[:-1], "RLEG_JOINT9"))
    with pytest.raises(EstimationError, match="LARM_JOINT6"):
        JointAddress.by_name(model, JOINT_NAMES[:-1])


def test_bodies_beyond_the_sensors_are_the_foot_and_the_hand_with_its_gripper():
    """Ankle: the 1 kg foot, no joint; wrist: the 0.4 kg hand welded plus the gripper joint beyond."""
    robot = EstimatorModel(info_with(JOINT_NAMES), EstimatorConfig())
    m = robot.model
    ankle, wrist = robot.ft[0], robot.ft[2]
    assert ankle.name == "right_ankle" and ankle.welded_inertia.mass == pytest.approx(1.0)
    assert ankle.distal_joints == () and m.names[ankle.parent_joint] == "RLEG_JOINT5"
    assert wrist.welded_inertia.mass == pytest.approx(0.4)
    assert [m.names[j] for j in wrist.distal_joints] == ["RARM_JOINT6"]
    # Foot CoM in its own (locked joint) frame, and that frame 0.085 m below the ankle roll axis.
    assert np.allclose(ankle.welded_inertia.lever, [0.0496, -0.0243, -0.01])
    assert np.allclose(m.jointPlacements[ankle.joint_id].translation, [0.0, 0.0, -0.085])
    assert m.inertias[ankle.parent_joint].mass == pytest.approx(0.8)  # the ankle roll link alone
    assert robot.model.gravity.linear.tolist() == [0.0, 0.0, 0.0]
    assert [m.names[j] for j in robot.unknown_path] == ["CHEST_JOINT0", "CHEST_JOINT1"]


def test_split_model_has_the_same_dynamics():
    """Splitting the bodies beyond the sensors onto locked joints changes no torque, frame or mass."""
    original = load_pinocchio(MODEL_PATH)
    frames = dict(FT_FRAMES)
    split, locked = split_sensor_bodies(original, frames)
    assert split.nv == original.nv + 4 and len(locked) == 4
    rng = np.random.default_rng(5)
    q0, v0, a0 = pin.randomConfiguration(original), rng.standard_normal(original.nv), rng.standard_normal(original.nv)
    q1, v1, a1 = pin.neutral(split), np.zeros(split.nv), np.zeros(split.nv)
    q1[0:7] = q0[0:7]
    v1[0:6], a1[0:6] = v0[0:6], a0[0:6]
    rows0, rows1 = [], []
    for name in JOINT_NAMES:
        j0, j1 = original.getJointId(name), split.getJointId(name)
        q1[split.idx_qs[j1]], v1[split.idx_vs[j1]], a1[split.idx_vs[j1]] = (
            q0[original.idx_qs[j0]], v0[original.idx_vs[j0]], a0[original.idx_vs[j0]])
        rows0.append(original.idx_vs[j0])
        rows1.append(split.idx_vs[j1])
    tau0 = pin.rnea(original, original.createData(), q0, v0, a0)
    tau1 = pin.rnea(split, split.createData(), q1, v1, a1)
    assert np.allclose(tau1[rows1], tau0[rows0], atol=1e-9) and np.allclose(tau1[:6], tau0[:6], atol=1e-9)
    d0, d1 = original.createData(), split.createData()
    pin.framesForwardKinematics(original, d0, q0)
    pin.framesForwardKinematics(split, d1, q1)
    for name in ("imu", "ft_right_wrist", "ft_left_ankle", "RARM_LINK6", "CHEST_LINK1"):
        assert d1.oMf[split.getFrameId(name)].isApprox(d0.oMf[original.getFrameId(name)], 1e-12)
    assert pin.computeTotalMass(split) == pytest.approx(pin.computeTotalMass(original))


def test_dependencies_follow_the_kinematic_tree():
    """The right knee torque uses right-leg encoders and the right ankle F/T, not the left leg's."""
    robot = EstimatorModel(info_with(JOINT_NAMES), EstimatorConfig())
    enc, ft, ft_enc = robot.dependencies()
    knee, ankle = JOINT_NAMES.index("RLEG_JOINT3"), JOINT_NAMES.index("RLEG_JOINT4")
    assert enc[ankle, knee] and enc[knee, ankle] and not enc[knee, JOINT_NAMES.index("LLEG_JOINT3")]
    assert ft[knee].tolist() == [True, False, False, False]
    chest = JOINT_NAMES.index("CHEST_JOINT1")  # between the base and the unknown-wrench body: everything
    assert enc[chest].all() and ft[chest].all()
    assert ft_enc[2, JOINT_NAMES.index("RARM_JOINT6")] and not ft_enc[2, knee]


def test_perturbation_is_seeded_and_keeps_welded_frames_consistent():
    """Masses change by the seeded draw; joint inertia = own + welded frames; std 0 changes nothing."""
    model = load_pinocchio(MODEL_PATH)
    same = perturb_inertias(model, ModelPerturbation())
    assert all(same.inertias[j] == model.inertias[j] for j in range(model.njoints))
    a = perturb_inertias(model, ModelPerturbation(0.1, 0.01, seed=3))
    b = perturb_inertias(model, ModelPerturbation(0.1, 0.01, seed=3))
    masses = np.array([a.inertias[j].mass for j in range(1, a.njoints)])
    assert np.array_equal(masses, [b.inertias[j].mass for j in range(1, b.njoints)])
    nominal = np.array([model.inertias[j].mass for j in range(1, model.njoints)])
    assert 0.02 < np.std(masses / nominal - 1.0) < 0.3
    foot = [f for f in range(a.nframes) if a.frames[f].name == "RLEG_FOOT_fixed"][0]
    j = a.frames[foot].parentJoint
    own_nominal = model.inertias[j] - model.frames[foot].placement.act(model.frames[foot].inertia)
    own = a.inertias[j] - a.frames[foot].placement.act(a.frames[foot].inertia)
    assert own.mass != pytest.approx(own_nominal.mass, rel=1e-6)
    assert a.frames[foot].inertia.mass != pytest.approx(1.0, rel=1e-6)
    assert isinstance(own, pin.Inertia) and own.mass > 0
