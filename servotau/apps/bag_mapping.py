"""The mapping file of ``servotau log convert``: which ROS bag topics give which columns of the HAL's log.

Example (every table but ``[joint_state]`` optional)::

    [robot]
    name = "my_robot"           # RobotInfo.name (default "bag")
    model = "hrp2"              # MJCF file of the robot, or "hrp2": the package's model (default)
    period = 0.001              # [s] control period (default: the median step of the joint_state stamps)
    stamp = "header"            # time of a message: "header" (header.stamp, default) or "bag" (receive time)

    [joint_state]               # sensor_msgs/JointState: q/<joint> from position; one log row per message
    topic = "/joint_states"
    velocity = false            # true: velocity -> est/dq/<joint> [rad/s] (the workbench's velocity)
    effort = false              # true: effort -> est/tau/<joint> [N m] (the workbench's torque)

    [joint_command]             # sensor_msgs/JointState: q_des/<joint> from position (what identification fits)
    topic = "/joint_commands"

    [joints]                    # bag name = HAL name (default: the bag's names)
    r_hip_yaw = "RLEG_JOINT0"

    [imu]                       # sensor_msgs/Imu: imu/gyro_x|y|z [rad/s], imu/acc_x|y|z [m/s^2]
    topic = "/imu"

    [ft.right_ankle]            # geometry_msgs/WrenchStamped: ft/right_ankle/fx..tz [N, N m]
    topic = "/ft/right_ankle"   # (sensor names: the HAL's, servotau.hal.types.FT_SENSOR_NAMES)

The log's joints are the joint_state message's (renamed), each a joint of the model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from servotau.config import Section, load_toml
from servotau.hal.types import FT_SENSOR_NAMES

JOINT_STATE = "sensor_msgs/msg/JointState"
IMU = "sensor_msgs/msg/Imu"
WRENCH = "geometry_msgs/msg/WrenchStamped"
TOP_KEYS = ("robot", "joint_state", "joint_command", "joints", "imu", "ft")


@dataclass(frozen=True)
class Topic:
    """One mapped topic: its name, the message type it must carry and the mapping field that named it."""

    topic: str
    msgtype: str
    field: str  # e.g. "joint_state.topic", for errors


@dataclass(frozen=True)
class BagMapping:
    """A parsed mapping file (module doc)."""

    file: str
    joint_state: Topic
    joint_command: Topic | None = None
    imu: Topic | None = None
    ft: dict[str, Topic] = field(default_factory=dict)  # HAL sensor name -> topic
    rename: dict[str, str] = field(default_factory=dict)  # bag joint name -> HAL joint name
    velocity: bool = False
    effort: bool = False
    name: str = "bag"
    model: str = "hrp2"
    period: float | None = None  # [s]
    stamp: str = "header"

    def topics(self) -> list[Topic]:
        """Every mapped topic, joint_state first."""
        return [t for t in (self.joint_state, self.joint_command, self.imu, *self.ft.values()) if t is not None]

    def hal_name(self, bag_joint: str) -> str:
        return self.rename.get(bag_joint, bag_joint)


def _topic(sec: Section, msgtype: str, extra: tuple[str, ...] = ()) -> Topic:
    sec.check_keys(("topic", *extra))
    return Topic(sec.str("topic"), msgtype, f"{sec.prefix}.topic" if sec.prefix else "topic")


def load_mapping(path: str | Path) -> BagMapping:
    """Read and check a mapping file; errors name the file, the field and the expected value."""
    root = load_toml(path)
    root.check_keys(TOP_KEYS)
    robot = root.section("robot", {})
    robot.check_keys(("name", "model", "period", "stamp"))
    js = root.section("joint_state")
    joint_state = _topic(js, JOINT_STATE, ("velocity", "effort"))
    cmd = _topic(root.section("joint_command"), JOINT_STATE) if "joint_command" in root else None
    imu = _topic(root.section("imu"), IMU) if "imu" in root else None
    ft_sec = root.section("ft", {})
    ft_sec.check_keys(FT_SENSOR_NAMES)
    ft = {s: _topic(ft_sec.section(s), WRENCH) for s in FT_SENSOR_NAMES if s in ft_sec}
    names = root.section("joints", {})
    rename = {k: names.str(k) for k in names.keys()}
    hal = list(rename.values())
    dup = sorted({n for n in hal if hal.count(n) > 1})
    if dup:
        raise names.error(next(k for k, v in rename.items() if v == dup[0]), dup[0],
                          "a HAL joint name given to one bag joint only")
    period = robot.float("period", None, min=0.0, strict_min=True, unit="s") if "period" in robot else None
    return BagMapping(
        file=root.file, joint_state=joint_state, joint_command=cmd, imu=imu, ft=ft, rename=rename,
        velocity=js.bool("velocity", False), effort=js.bool("effort", False), name=robot.str("name", "bag"),
        model=robot.str("model", "hrp2"), period=period, stamp=robot.str("stamp", "header", choices=("header", "bag")))
