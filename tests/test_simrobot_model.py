"""The robot model file (servotau.description) in MuJoCo and Pinocchio, and the MuJoCo <-> Pinocchio helpers."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from servotau import description
from servotau.errors import ConfigError, ServotauError
from servotau.simrobot import model as hrp2

G = 9.81  # [m/s^2]

# Public figures (docs: hrp2-public-figures.md), HRP-2 order.
LIMITS = [
    (-0.785398, 0.523599), (-0.610865, 0.349066), (-2.18166, 0.733038), (-0.0349066, 2.61799),
    (-1.309, 0.733038), (-0.349066, 0.610865),
    (-0.523599, 0.785398), (-0.349066, 0.610865), (-2.18166, 0.733038), (-0.0349066, 2.61799),
    (-1.309, 0.733038), (-0.610865, 0.349066),
    (-0.785398, 0.785398), (-0.0872665, 1.0472), (-0.785398, 0.78539), (-0.523599, 0.785398),
    (-3.14159, 1.0472), (-1.65806, 0.174533), (-1.6057, 1.6057), (-2.3911, 0.0349066),
    (-1.6057, 1.6057), (-1.6057, 1.6057), (-1.0, 1.0),
    (-3.14159, 1.0472), (-0.174533, 1.65806), (-1.6057, 1.6057), (-2.3911, 0.0349066),
    (-1.6057, 1.6057), (-1.6057, 1.6057), (-1.0, 1.0),
]
_LEG_GEAR, _LEG_ROTOR = [384, 240, 180, 200, 180, 100], [1.01e-6, 6.96e-6, 1.34e-5, 1.34e-5, 6.96e-6, 6.96e-6]
_ARM_GEAR = [219.23, 231.25, 266.67, 250.0, 145.45, 350.0, 200.0]
_ARM_ROTOR = [6.96e-6, 6.60e-6, 1.00e-6, 6.60e-6, 1.10e-6, 1.00e-6, 5.818e-7]
GEAR = _LEG_GEAR * 2 + [207.69, 381.54, 100, 100] + _ARM_GEAR * 2
ROTOR = _LEG_ROTOR * 2 + [6.96e-6, 6.96e-6, 1.0e-6, 1.0e-6] + _ARM_ROTOR * 2  # head: assumed 1e-6


@pytest.fixture(scope="module")
def mj_model():
    return hrp2.load_mujoco()


@pytest.fixture(scope="module")
def pin_model():
    return description.load_pinocchio()


def _locked_robot(weld_base: bool, base_height: float):
    """Robot in half-sitting with every joint held by an equality constraint, settled for 0.5 s."""
    spec = mujoco.MjSpec.from_file(str(description.MODEL_PATH))
    m0 = hrp2.load_mujoco()
    q_hs = hrp2.half_sitting_qpos(m0)
    for name in description.JOINT_NAMES:
        eq = spec.add_equality()
        eq.type, eq.objtype, eq.name1 = mujoco.mjtEq.mjEQ_JOINT, mujoco.mjtObj.mjOBJ_JOINT, name
        eq.solref = [0.005, 1.0]  # [s] stiff, critically damped: settles within 0.5 s
        data = np.zeros(len(eq.data))
        data[0] = q_hs[m0.joint(name).qposadr[0]]
        eq.data = data
    if weld_base:
        spec.body("BODY").pos = [0.0, 0.0, base_height]  # qpos0, held there by the weld
        eq = spec.add_equality()
        eq.type, eq.objtype, eq.name1 = mujoco.mjtEq.mjEQ_WELD, mujoco.mjtObj.mjOBJ_BODY, "BODY"
        eq.solref = [0.005, 1.0]
        data = np.zeros(len(eq.data))  # zero relpose quaternion: keep the qpos0 pose; anchor at origin
        data[10] = 1.0  # torquescale
        eq.data = data
    m = spec.compile()
    d = mujoco.MjData(m)
    d.qpos[:] = q_hs
    d.qpos[2] = base_height
    for _ in range(500):
        mujoco.mj_step(m, d)
    mujoco.mj_forward(m, d)
    return m, d


def _hal_wrench(m, d, sensor: str) -> np.ndarray:
    site = description.FT_FRAMES[sensor]
    return hrp2.mujoco_wrench_to_hal(np.concatenate([d.sensor(f"{site}_force").data, d.sensor(f"{site}_torque").data]))


def _random_state(m, rng):
    qpos = np.zeros(m.nq)
    qpos[0:3] = rng.uniform(-1.0, 1.0, 3) + [0.0, 0.0, 3.0]  # high enough: no contact
    quat = rng.normal(size=4)
    qpos[3:7] = quat / np.linalg.norm(quat)
    for name in description.JOINT_NAMES:
        lo, hi = m.joint(name).range
        qpos[m.joint(name).qposadr[0]] = rng.uniform(lo + 1e-3, hi - 1e-3)
    return qpos, rng.normal(size=m.nv), rng.normal(size=m.nv)


def test_loads_in_both_libraries(mj_model, pin_model):
    """MuJoCo and Pinocchio load the file with a free-flyer root and the same 30 joint names."""
    assert (mj_model.nq, mj_model.nv) == (pin_model.nq, pin_model.nv) == (37, 36)
    assert list(pin_model.names)[1:] == [description.ROOT_JOINT, *description.JOINT_NAMES]
    assert pin_model.joints[1].shortname() == "JointModelFreeFlyer"
    assert mj_model.jnt_type[mj_model.joint(description.ROOT_JOINT).id] == mujoco.mjtJoint.mjJNT_FREE
    assert mj_model.body(mj_model.joint(description.ROOT_JOINT).bodyid[0]).name == "BODY"
    jm = hrp2.JointMap.from_models(mj_model, pin_model)
    assert [mj_model.joint(n).qposadr[0] for n in description.JOINT_NAMES] == list(jm.mj_qpos)


def test_joint_limits_match_public_table(mj_model, pin_model):
    """Every joint is a limited hinge with the public limits, in MuJoCo and in Pinocchio."""
    jm = hrp2.default_joint_map()
    for name, (lo, hi), iq in zip(description.JOINT_NAMES, LIMITS, jm.pin_q, strict=True):
        j = mj_model.joint(name)
        assert j.type[0] == mujoco.mjtJoint.mjJNT_HINGE and mj_model.jnt_limited[j.id]
        np.testing.assert_allclose(j.range, [lo, hi], atol=1e-12, err_msg=name)
        assert pin_model.lowerPositionLimit[iq] == pytest.approx(lo, abs=1e-12)
        assert pin_model.upperPositionLimit[iq] == pytest.approx(hi, abs=1e-12)


def test_armature_is_reflected_rotor_inertia_and_no_friction(mj_model, pin_model):
    """armature = gear^2 * rotor inertia in both libraries; no joint damping or frictionloss."""
    jm = hrp2.default_joint_map()
    expected = np.array(GEAR) ** 2 * np.array(ROTOR)
    np.testing.assert_allclose(mj_model.dof_armature[jm.mj_dof], expected, rtol=1e-5)
    np.testing.assert_allclose(pin_model.armature[jm.pin_v], expected, rtol=1e-5)
    assert not np.any(mj_model.dof_damping) and not np.any(mj_model.dof_frictionloss)


def test_total_mass(mj_model, pin_model):
    """The robot weighs 57-59 kg, the same in both libraries."""
    mass = mj_model.body_subtreemass[mj_model.body("BODY").id]
    assert 57.0 <= mass <= 59.0
    assert sum(pin_model.inertias[i].mass for i in range(pin_model.njoints)) == pytest.approx(mass, abs=1e-9)


def test_mass_matrix_and_rnea_agree(mj_model, pin_model):
    """M(q) and inverse dynamics (gravity, armature) agree to 1e-9 at random states."""
    d, pdata = mujoco.MjData(mj_model), pin_model.createData()
    rng = np.random.default_rng(1)
    m_mj = np.zeros((mj_model.nv, mj_model.nv))
    for _ in range(5):
        qpos, qvel, qacc = _random_state(mj_model, rng)
        d.qpos[:], d.qvel[:], d.qacc[:] = qpos, qvel, qacc
        mujoco.mj_inverse(mj_model, d)
        assert d.ncon == 0 and d.nefc == 0  # pure rigid-body dynamics
        mujoco.mj_fullM(mj_model, d, m_mj)
        q, v = hrp2.mujoco_to_pinocchio_state(qpos, qvel)
        a = hrp2.mujoco_to_pinocchio_acceleration(qpos, qvel, qacc)
        m_pin = pin.crba(pin_model, pdata, q)
        m_pin = np.triu(m_pin) + np.triu(m_pin, 1).T
        tau = pin.rnea(pin_model, pdata, q, v, a)
        np.testing.assert_allclose(m_pin, hrp2.mujoco_to_pinocchio_mass_matrix(qpos, m_mj), rtol=0, atol=1e-9)
        np.testing.assert_allclose(tau, hrp2.mujoco_to_pinocchio_force(qpos, d.qfrc_inverse), rtol=0, atol=1e-9)


def test_state_conversion_round_trip_and_kinematics(mj_model, pin_model):
    """State conversions invert each other and both libraries place the sensor sites identically."""
    d, pdata = mujoco.MjData(mj_model), pin_model.createData()
    qpos, qvel, _ = _random_state(mj_model, np.random.default_rng(2))
    q, v = hrp2.mujoco_to_pinocchio_state(qpos, qvel)
    qpos2, qvel2 = hrp2.pinocchio_to_mujoco_state(q, v)
    np.testing.assert_allclose(qpos2, qpos, atol=1e-15)
    np.testing.assert_allclose(qvel2, qvel, atol=1e-14)
    np.testing.assert_allclose(q[3:7], qpos[[4, 5, 6, 3]])  # xyzw vs wxyz
    d.qpos[:], d.qvel[:] = qpos, qvel
    mujoco.mj_forward(mj_model, d)
    pin.framesForwardKinematics(pin_model, pdata, q)
    for site in [*description.FT_FRAMES.values(), "imu"]:
        oMf = pdata.oMf[pin_model.getFrameId(site)]
        np.testing.assert_allclose(oMf.translation, d.site(site).xpos, atol=1e-12)
        np.testing.assert_allclose(oMf.rotation, d.site(site).xmat.reshape(3, 3), atol=1e-12)
    with pytest.raises(ServotauError):
        hrp2.mujoco_to_pinocchio_state(qpos[:-1], qvel)


def test_half_sitting_soles_on_floor_and_com(mj_model, pin_model):
    """In the half-sitting keyframe both soles are at z = 0 (+/- 2 mm) and the CoM is near 0.81 m."""
    d = mujoco.MjData(mj_model)
    d.qpos[:] = hrp2.half_sitting_qpos(mj_model)
    assert d.qpos[2] == pytest.approx(0.648702)
    mujoco.mj_forward(mj_model, d)
    for geom in ("right_sole", "left_sole"):
        g = d.geom(geom)
        half = mj_model.geom(geom).size
        signs = np.array(np.meshgrid(*[[-1, 1]] * 3)).T.reshape(-1, 3)
        lowest = min((g.xpos + g.xmat.reshape(3, 3) @ (half * s))[2] for s in signs)
        assert lowest == pytest.approx(0.0, abs=2e-3), geom
    com = d.subtree_com[mj_model.body("BODY").id]
    print(f"half-sitting CoM: {com} [m]")
    assert 0.7 < com[2] < 0.9
    q_ref = pin_model.referenceConfigurations[description.HALF_SITTING]  # Pinocchio reads the keyframe too
    np.testing.assert_allclose(q_ref, hrp2.mujoco_to_pinocchio_state(d.qpos, d.qvel).q, atol=1e-12)
    assert pin.centerOfMass(pin_model, pin_model.createData(), q_ref)[2] == pytest.approx(com[2], abs=1e-12)


def test_height_at_zero_posture(mj_model):
    """With straight legs the robot is about 1.54 m from sole to head top."""
    d = mujoco.MjData(mj_model)
    mujoco.mj_forward(mj_model, d)  # qpos0: legs straight, base at its MJCF position
    head = [g for g in range(mj_model.ngeom) if mj_model.body(mj_model.geom_bodyid[g]).name == "HEAD_LINK1"][0]
    top = d.geom_xpos[head][2] + mj_model.geom_size[head][2]
    sole = d.geom("right_sole").xpos[2] - mj_model.geom("right_sole").size[2]
    assert top - sole == pytest.approx(1.54, abs=0.01)


def test_only_feet_and_hands_touch_only_the_floor(mj_model):
    """Collision is on for soles and hands against the floor only: no robot self-collision."""
    def collides(a, b):
        return bool(mj_model.geom_contype[a] & mj_model.geom_conaffinity[b]
                    or mj_model.geom_contype[b] & mj_model.geom_conaffinity[a])
    floor = mj_model.geom("floor").id
    robot = [g for g in range(mj_model.ngeom) if g != floor]
    colliding = {mj_model.geom(g).name for g in robot if collides(g, floor)}
    assert colliding == {"right_sole", "left_sole", "right_hand", "left_hand"}
    assert not any(collides(a, b) for a in robot for b in robot)
    assert all(mj_model.geom(n).condim[0] == 3 for n in colliding)


def test_ft_sign_hanging_foot():
    """A foot hanging free pulls its leg down: HAL fz = -m_foot g and the torque of its weight."""
    m, d = _locked_robot(weld_base=True, base_height=1.5)
    assert d.ncon == 0
    for sensor, body in (("right_ankle", "RLEG_FOOT"), ("left_ankle", "LLEG_FOOT")):
        mass, com = m.body(body).mass[0], m.body(body).ipos  # CoM in the foot (= sensor) frame
        rot = d.site(description.FT_FRAMES[sensor]).xmat.reshape(3, 3)  # about level in half-sitting
        weight = rot.T @ [0.0, 0.0, -mass * G]  # in the sensor frame
        expected = np.concatenate([weight, np.cross(com, weight)])
        np.testing.assert_allclose(_hal_wrench(m, d, sensor), expected, atol=1e-2)
        assert _hal_wrench(m, d, sensor)[2] < -0.99 * mass * G
    for sensor, body in (("right_wrist", "RARM_HAND"), ("left_wrist", "LARM_HAND")):
        mass = m.body(body).subtreemass[0]  # hand and gripper
        rot = d.site(description.FT_FRAMES[sensor]).xmat.reshape(3, 3)
        np.testing.assert_allclose(rot @ _hal_wrench(m, d, sensor)[:3], [0.0, 0.0, -mass * G], atol=1e-2)


def test_ft_sign_standing_and_imu_at_rest():
    """Standing still, both ankles read fz > 0 summing to the weight above them; the IMU reads +g."""
    m, d = _locked_robot(weld_base=False, base_height=hrp2.half_sitting_qpos()[2])
    assert np.abs(d.qvel).max() < 1e-2  # settled
    fz = [_hal_wrench(m, d, s)[2] for s in ("right_ankle", "left_ankle")]
    feet = m.body("RLEG_FOOT").mass[0] + m.body("LLEG_FOOT").mass[0]
    assert min(fz) > 0.4 * m.body("BODY").subtreemass[0] * G
    assert sum(fz) == pytest.approx((m.body("BODY").subtreemass[0] - feet) * G, rel=1e-3)
    np.testing.assert_allclose(d.sensor("imu_accel").data, [0.0, 0.0, G], atol=0.05)
    np.testing.assert_allclose(d.sensor("imu_gyro").data, 0.0, atol=1e-2)


def test_imu_and_lift_sites(mj_model):
    """The IMU site is at (-0.13, 0, 0.118) m in CHEST_LINK1, level; lift sites are on the chest."""
    chest = mj_model.body("CHEST_LINK1").id
    imu = mj_model.site("imu")
    assert imu.bodyid[0] == chest
    np.testing.assert_allclose(imu.pos, [-0.13, 0.0, 0.118])
    np.testing.assert_allclose(imu.quat, [1.0, 0.0, 0.0, 0.0])
    assert mj_model.site("lift_right").bodyid[0] == mj_model.site("lift_left").bodyid[0] == chest
    assert mj_model.site("lift_right").pos[1] < 0 < mj_model.site("lift_left").pos[1]


def test_ft_sensor_bodies_and_sites(mj_model):
    """F/T sites sit at the origin of welded bodies at the public placements."""
    for side in ("right", "left"):
        s = "R" if side == "right" else "L"
        foot = mj_model.body(f"{s}LEG_FOOT")
        assert foot.jntnum[0] == 0 and mj_model.body(foot.parentid[0]).name == f"{s}LEG_LINK5"
        np.testing.assert_allclose(foot.pos, [0.0, 0.0, -0.085])
        hand = mj_model.body(f"{s}ARM_HAND")
        assert hand.jntnum[0] == 0 and mj_model.body(hand.parentid[0]).name == f"{s}ARM_LINK5"
        np.testing.assert_allclose(hand.pos, [0.005, 0.0, -0.05925])
        np.testing.assert_allclose(hand.quat, [np.cos(-np.pi / 4), 0.0, 0.0, np.sin(-np.pi / 4)])
        assert mj_model.body(mj_model.joint(f"{s}ARM_JOINT6").bodyid[0]).parentid[0] == hand.id
        for part, body in (("ankle", foot), ("wrist", hand)):
            site = mj_model.site(f"ft_{side}_{part}")
            assert site.bodyid[0] == body.id and not np.any(site.pos)
            np.testing.assert_allclose(site.quat, [1.0, 0.0, 0.0, 0.0])


def test_mujoco_wrench_to_hal_flips_sign():
    """The conversion negates MuJoCo's proximal-on-distal readings, one or stacked, and checks shapes."""
    w = np.arange(24.0).reshape(4, 6)
    np.testing.assert_allclose(hrp2.mujoco_wrench_to_hal(w), -w)
    np.testing.assert_allclose(hrp2.mujoco_wrench_to_hal(w[1]), -w[1])
    with pytest.raises(ServotauError):
        hrp2.mujoco_wrench_to_hal(np.zeros(3))


def test_unknown_keyframe_raises_config_error(mj_model):
    """Asking for a keyframe that does not exist raises ConfigError listing the keyframes."""
    with pytest.raises(ConfigError, match="half_sitting"):
        hrp2.keyframe_qpos(mj_model, "squat")


def test_missing_file_raises_config_error(tmp_path):
    """Loading a file that does not exist raises ConfigError naming the file."""
    for load in (hrp2.load_mujoco, description.load_pinocchio):
        with pytest.raises(ConfigError, match="nope.xml"):
            load(tmp_path / "nope.xml")
