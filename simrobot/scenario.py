"""Scenarios: where the robot is and what touches it (lift strings, floor, block, operator pushes).

The robot model file stays the single source of the robot; a scenario only adds world elements
(anchors, strings, a block) through MuJoCo's model editing API, so Pinocchio and MuJoCo still read
the same robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from servotau.config import Section, load_dataclass, load_toml, setting

PROFILES = ("constant", "ramp", "sine")
"""Push profiles: constant, ramp (0 -> peak -> 0, triangular) or sine."""


@dataclass(frozen=True)
class OperatorPush:
    """A scripted external wrench on one body, in the world frame, applied at the body's centre of
    mass (the paper's hand pushes that load the joints for high-torque identification data)."""

    body: str = setting()
    start: float = setting(unit="s", min=0)  # sim time
    duration: float = setting(unit="s", min=0, strict_min=True)
    force: np.ndarray = setting(unit="N", shape=(3,), factory=lambda: np.zeros(3))  # world frame (the peak value
    # for "ramp" and "sine")
    torque: np.ndarray = setting(unit="N m", shape=(3,), factory=lambda: np.zeros(3))  # world frame
    profile: str = setting("constant", choices=PROFILES)
    frequency: float = setting(0.5, unit="Hz", min=0, strict_min=True)  # for "sine"

    def scale(self, t: float) -> float:
        """Profile value in [-1, 1] at sim time ``t`` [s] (0 outside the push)."""
        s = t - self.start
        if s < 0.0 or s > self.duration:
            return 0.0
        if self.profile == "ramp":
            return 1.0 - abs(2.0 * s / self.duration - 1.0)
        if self.profile == "sine":
            return math.sin(2.0 * math.pi * self.frequency * s)
        return 1.0

    @classmethod
    def from_section(cls, sec: Section) -> OperatorPush:
        return load_dataclass(cls, sec)


@dataclass(frozen=True)
class Scenario:
    name: str = setting()
    initial_posture: str = setting("half_sitting")  # a keyframe of the model
    base_height: float = setting(0.648702, unit="m", min=0, max=3)  # initial waist height
    floor: bool = setting(True)
    lift: bool = setting(False)  # two strings from anchors above the shoulders
    string_length: float = setting(0.6, unit="m", min=0.05, max=5)  # anchor to shoulder at the initial posture
    string_slack: float = setting(0.0, unit="m", min=0, max=1)  # extra length: > 0 leaves the strings slack
    string_damping: float = setting(200.0, unit="N s/m", min=0)
    base_damping: float = setting(0.0, unit="N m s/rad", min=0)  # on the base rotation
    block_height: float = setting(0.0, unit="m", min=0, max=0.2)  # 0: no block; else a block under the right foot
    operator: tuple[OperatorPush, ...] = ()  # [[operator]] tables

    @classmethod
    def from_toml(cls, path: str | Path) -> Scenario:
        root = load_toml(path)
        raw_ops = root.data.get("operator", [])
        if not isinstance(raw_ops, list) or not all(isinstance(o, dict) for o in raw_ops):
            raise root.error("operator", raw_ops, "an array of tables [[operator]]")
        ops = tuple(OperatorPush.from_section(Section(o, root.file, f"operator[{i}]")) for i, o in enumerate(raw_ops))
        return load_dataclass(cls, root, ignore=["operator"], operator=ops)


def bend_right_leg_for_block(qpos_leg: np.ndarray, height: float, thigh: float = 0.30, shin: float = 0.30) -> None:
    """Raise the right sole by ``height`` [m] keeping it flat: bend the knee and share the change
    between hip and ankle pitch (in place on the 6 right-leg angles)."""
    hip, knee, ankle = qpos_leg[2], qpos_leg[3], qpos_leg[4]
    d = math.sqrt(thigh**2 + shin**2 + 2 * thigh * shin * math.cos(knee))  # hip-ankle distance
    d_new = d - height
    knee_new = math.acos((d_new**2 - thigh**2 - shin**2) / (2 * thigh * shin))
    # Keep the hip-to-ankle direction: the thigh turns by half the knee change (equal links).
    delta = (knee_new - knee) / 2.0
    qpos_leg[2], qpos_leg[3], qpos_leg[4] = hip - delta, knee_new, ankle - delta


def build_model(model_path: str | Path, scenario: Scenario, qpos0: np.ndarray) -> mujoco.MjModel:
    """Compile the robot file with the scenario's world elements for the initial state ``qpos0``."""
    spec = mujoco.MjSpec.from_file(str(model_path))
    if not scenario.floor:
        for g in spec.geoms:
            if g.name == "floor":
                spec.delete(g)
    if scenario.lift or scenario.block_height > 0:
        model = spec.compile()
        data = mujoco.MjData(model)
        data.qpos[:] = qpos0
        mujoco.mj_kinematics(model, data)
        if scenario.lift:
            for side in ("right", "left"):
                p = data.site(f"lift_{side}").xpos.copy()
                spec.worldbody.add_site(name=f"anchor_{side}", pos=p + [0, 0, scenario.string_length])
                length = scenario.string_length + scenario.string_slack
                t = spec.add_tendon(name=f"string_{side}", limited=True, range=[0.0, length])
                t.damping = [scenario.string_damping, 0.0, 0.0]
                t.wrap_site(f"anchor_{side}")
                t.wrap_site(f"lift_{side}")
        if scenario.block_height > 0:
            sole = data.geom("right_sole")
            top = scenario.block_height
            spec.worldbody.add_geom(
                name="block",
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=[0.2, 0.15, top / 2],
                pos=[sole.xpos[0], sole.xpos[1], top / 2],
                rgba=[0.6, 0.3, 0.2, 1.0],
                contype=1,  # like the floor: touches the robot's collision geoms only
                conaffinity=2,
            )
    return spec.compile()
