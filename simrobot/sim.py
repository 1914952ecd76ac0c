"""The simulated HRP-2: MuJoCo rigid-body dynamics, the closed position servo, sensors, scenario.

In-process API (the HAL's ``servotau sim`` process serves this over Zenoh)::

    robot = SimRobot.from_config("sim.toml")
    frame = robot.read()                  # SensorFrame of the current tick
    robot.step(q_des)                     # desired angles [rad], RobotInfo joint order, one period
    truth = robot.ground_truth()          # evaluation only: the controller never reads it

Each tick: the servo turns the desired angles into current and torque from the state at the start
of the tick, MuJoCo integrates one period (several sub-steps when a gear is elastic), then the
sensors are computed at the new state with the torque held (zero-order hold, as on the robot).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import mujoco
import numpy as np

from servotau.config import CONFIG_DIR, load_dataclass, load_toml, resolve_config_path, setting
from servotau.description import FT_FRAMES, FT_SENSOR_NAMES, JOINT_NAMES, MODEL_PATH, ROOT_JOINT
from servotau.errors import ConfigError
from servotau.hal.types import GroundTruth, RobotInfo, SensorFrame

from . import model as robot_model
from .scenario import OperatorPush, Scenario, bend_right_leg_for_block, build_model
from .sensors import SensorConfig, SensorModel
from .servo import Servo
from .servo_config import load_servo_params

FLEX_SUBSTEPS = 4  # sub-steps per tick when a joint has an elastic gear or backlash
DEFAULT_SCENARIO = "scenarios/hanging.toml"
"""The scenario of a sim file without ``scenario`` (relative to config/)."""


@dataclass(frozen=True)
class SimConfig:
    """Everything that defines a simulation run (file paths resolved against config/)."""

    scenario: Scenario
    servo_path: Path = CONFIG_DIR / "servo.toml"
    sensors: SensorConfig = field(default_factory=lambda: SensorConfig.from_toml(CONFIG_DIR / "sensors.toml"))
    model_path: Path = MODEL_PATH
    seed: int = setting(0, min=0)
    effects: dict | None = None  # overrides servo.toml's [effects] table

    @classmethod
    def from_toml(cls, path: str | Path) -> SimConfig:
        """Read a sim file: ``scenario``, ``servo``, ``sensors`` (paths relative to config/, each optional),
        ``seed`` and ``effects``."""
        root = load_toml(path)
        files = {"servo": "servo_path", "sensors": "sensors"}
        given = {field_: resolve_config_path(root.str(key), root.file) for key, field_ in files.items() if key in root}
        if "sensors" in given:
            given["sensors"] = SensorConfig.from_toml(given["sensors"])
        scenario = Scenario.from_toml(resolve_config_path(root.str("scenario", DEFAULT_SCENARIO), root.file))
        return load_dataclass(cls, root, ignore=["scenario", *files, "effects"], scenario=scenario,
                              effects=dict(root.section("effects", {}).data) or None, **given)

    @classmethod
    def named(cls, scenario: str, **kwargs) -> SimConfig:
        """Config for ``config/scenarios/<scenario>.toml`` with defaults for the rest."""
        return cls(scenario=Scenario.from_toml(CONFIG_DIR / "scenarios" / f"{scenario}.toml"), **kwargs)


class SimRobot:
    """The simulated HRP-2, stepped one control period at a time."""

    def __init__(self, config: SimConfig):
        self.config = config
        sc = config.scenario
        base = mujoco.MjModel.from_xml_path(str(config.model_path))
        self.joint_names = JOINT_NAMES
        qpos0 = robot_model.keyframe_qpos(base, sc.initial_posture)
        qpos0[2] = sc.base_height
        self._qadr = np.array([base.joint(j).qposadr[0] for j in self.joint_names])
        self._dadr = np.array([base.joint(j).dofadr[0] for j in self.joint_names])
        if sc.block_height > 0:
            leg = qpos0[self._qadr[:6]].copy()
            bend_right_leg_for_block(leg, sc.block_height)
            qpos0[self._qadr[:6]] = leg
        m = build_model(config.model_path, sc, qpos0)
        self.model = m
        self.data = mujoco.MjData(m)
        self.period = float(m.opt.timestep)
        armature = m.dof_armature[self._dadr].copy()
        params = load_servo_params(config.servo_path, self.joint_names, armature, config.effects)
        self.servo = Servo(params, self.period)
        self._flex = np.flatnonzero(params.flexible)
        self._rigid = ~params.flexible  # joints whose damping MuJoCo integrates implicitly
        self.substeps = FLEX_SUBSTEPS if self._flex.size else 1
        if self.substeps > 1:
            m.opt.timestep = self.period / self.substeps
            m.dof_armature[self._dadr[self._flex]] = 0.0  # the rotor is simulated motor-side
        if sc.base_damping > 0:
            m.dof_damping[3:6] = sc.base_damping
        self._integrate = {
            mujoco.mjtIntegrator.mjINT_EULER: mujoco.mj_Euler,
            mujoco.mjtIntegrator.mjINT_RK4: mujoco.mj_RungeKutta,
        }.get(m.opt.integrator, mujoco.mj_implicit)
        self.rng = np.random.default_rng(config.seed)
        self.sensors = SensorModel(config.sensors, len(self.joint_names), self.rng)
        lo, hi = m.jnt_range[[m.joint(j).id for j in self.joint_names]].T
        self.info = RobotInfo(
            name="hrp2-sim", joint_names=self.joint_names, q_min=lo, q_max=hi, period=self.period,
            model_path=str(config.model_path), ft_sensor_names=FT_SENSOR_NAMES,
            ft_sensor_frames=tuple(FT_FRAMES[s] for s in FT_SENSOR_NAMES), root_joint=ROOT_JOINT,
        )
        self._ft_adr = [
            (m.sensor(f"{site}_force").adr[0], m.sensor(f"{site}_torque").adr[0]) for site in self.info.ft_sensor_frames
        ]
        self._gyro_adr = m.sensor("imu_gyro").adr[0]
        self._acc_adr = m.sensor("imu_accel").adr[0]
        self._ops = [(op, m.body(op.body).id) for op in sc.operator]
        self._sole_geoms = (m.geom("right_sole").id, m.geom("left_sole").id)
        self._tau = np.zeros(len(self.joint_names))
        self._ext = np.zeros(6)
        self.seq = 0
        # Motor-side state of flexible joints (angle [rad], velocity [rad/s]).
        self.data.qpos[:] = qpos0
        self._theta = self.data.qpos[self._qadr].copy()
        self._omega = np.zeros(len(self.joint_names))
        self._apply_operator(0.0)
        mujoco.mj_forward(m, self.data)
        self._frame = self._measure()

    # -- public API ----------------------------------------------------------------------------
    @classmethod
    def from_config(cls, path: str | Path) -> SimRobot:
        return cls(SimConfig.from_toml(path))

    @property
    def time(self) -> float:
        """Sim time [s] of the current tick."""
        return self.seq * self.period

    def read(self) -> SensorFrame:
        """Sensor frame of the current tick."""
        return self._frame

    def step(self, q_des: np.ndarray) -> None:
        """Hold desired angles ``q_des`` [rad] (RobotInfo order) for one period, then measure."""
        q_des = np.asarray(q_des, dtype=float)
        if q_des.shape != (len(self.joint_names),) or not np.all(np.isfinite(q_des)):
            raise ConfigError(f"q_des: expected {len(self.joint_names)} finite angles [rad], got {q_des!r}")
        m, d, sv = self.model, self.data, self.servo
        q_cmd = sv.delayed_command(q_des)
        self._apply_operator(self.time)
        for i in range(self.substeps):
            q_link, dq_link, q_m, dq_m = self._joint_state()
            if i == 0:  # the servo runs at the control rate: its torque is held over the sub-steps
                tau_motor = sv.motor_torque(q_cmd, q_m, dq_m)
            tau = tau_motor - sv.friction(q_m, dq_m)
            if self._flex.size:
                tau = self._flex_step(tau, q_link, dq_link)
            # The velocity-dependent part of the servo and friction is integrated implicitly:
            # MuJoCo applies -D dq_next as joint damping, so D dq is added back here.
            damp = sv.damping(dq_m) * self._rigid
            m.dof_damping[self._dadr] = damp
            d.qfrc_applied[self._dadr] = tau + damp * dq_link
            # New torque: recompute accelerations only, integrate, then evaluate the new state
            # (sensors included) with the torque held.
            mujoco.mj_forwardSkip(m, d, mujoco.mjtStage.mjSTAGE_VEL, 1)
            self._integrate(m, d)
            mujoco.mj_forward(m, d)
            self._tau = d.qfrc_applied[self._dadr] - damp * d.qvel[self._dadr]  # what acted on the links
        sv.tau_prev[:] = self._tau
        sv.heat()
        self.seq += 1
        self._frame = self._measure()

    def servo_off(self) -> None:
        """Cut every joint's servo (latched): no motor current from now on."""
        self.servo.enabled = False

    def servo_on(self) -> None:
        """Servos back on (the operator's reset of a latched servo-off, hal/robot/operator.py)."""
        self.servo.enabled = True

    def ground_truth(self) -> GroundTruth:
        """What actually happened at the current tick (evaluation only)."""
        d = self.data
        q = d.qpos[self._qadr].copy()
        dq = d.qvel[self._dadr].copy()
        return GroundTruth(
            time=self.time, seq=self.seq, q=q, dq=dq, tau=self._tau.copy(), current=self.servo.current.copy(),
            base_position=d.qpos[0:3].copy(), base_quat_wxyz=d.qpos[3:7].copy(),
            base_velocity=d.qvel[0:6].copy(), wrenches=self._true_wrenches(), external_wrench=self._ext.copy(),
            sole_contact_forces=self._sole_contact_forces(),
        )

    def add_push(self, push: OperatorPush) -> None:
        """Schedule an operator push (scripted external wrench) at run time."""
        self._ops.append((push, self.model.body(push.body).id))

    def with_seed(self, seed: int) -> SimRobot:
        return SimRobot(replace(self.config, seed=seed))

    # -- internals -----------------------------------------------------------------------------
    def _joint_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Link-side angle and velocity (views), and the motor-side ones (copies) that the servo and
        the encoders see: equal for rigid joints, the rotor state for elastic ones."""
        q_link, dq_link = self.data.qpos[self._qadr], self.data.qvel[self._dadr]
        q_m, dq_m = q_link.copy(), dq_link.copy()
        q_m[self._flex], dq_m[self._flex] = self._theta[self._flex], self._omega[self._flex]
        return q_link, dq_link, q_m, dq_m

    def _flex_step(self, tau_gear_in: np.ndarray, q_link: np.ndarray, dq_link: np.ndarray) -> np.ndarray:
        """Advance the motor side of elastic joints by one sub-step; return link-side torques."""
        p, f, h = self.servo.p, self._flex, self.model.opt.timestep
        defl = self._theta[f] - q_link[f]
        half = p.backlash[f] / 2.0
        spring = np.sign(defl) * np.maximum(np.abs(defl) - half, 0.0)
        engaged = (np.abs(defl) > half).astype(float)
        tau_link = p.gear_k[f] * spring + engaged * p.gear_d[f] * (self._omega[f] - dq_link[f])
        self._omega[f] += h * (tau_gear_in[f] - tau_link) / p.motor_inertia[f]
        self._theta[f] += h * self._omega[f]
        out = tau_gear_in.copy()
        out[f] = tau_link
        return out

    def _apply_operator(self, t: float) -> None:
        xfrc = self.data.xfrc_applied
        xfrc[:] = 0.0
        self._ext[:] = 0.0
        for op, body in self._ops:
            s = op.scale(t)
            if s != 0.0:
                w = s * np.concatenate([op.force, op.torque])
                xfrc[body] += w
                self._ext += w

    def _sole_contact_forces(self) -> np.ndarray:
        m, d = self.model, self.data
        out = np.zeros((2, 3))
        f6 = np.zeros(6)
        for i in range(d.ncon):
            c = d.contact[i]
            for k, sole in enumerate(self._sole_geoms):
                if sole in (c.geom1, c.geom2):
                    mujoco.mj_contactForce(m, d, i, f6)
                    world = c.frame.reshape(3, 3).T @ f6[:3]  # contact frame -> world: force on geom2
                    out[k] += world if c.geom2 == sole else -world
        return out

    def _true_wrenches(self) -> np.ndarray:
        sd = self.data.sensordata
        w = np.empty((len(FT_SENSOR_NAMES), 6))
        for k, (fa, ta) in enumerate(self._ft_adr):
            w[k, :3] = sd[fa : fa + 3]
            w[k, 3:] = sd[ta : ta + 3]
        return robot_model.mujoco_wrench_to_hal(w)

    def _measure(self) -> SensorFrame:
        sd = self.data.sensordata
        q_enc = self._joint_state()[2]  # the encoders sit on the motor side
        return self.sensors.measure(
            self.time, self.seq, q_enc, sd[self._gyro_adr : self._gyro_adr + 3].copy(),
            sd[self._acc_adr : self._acc_adr + 3].copy(), self._true_wrenches(),
        )
