"""Read the mapped topics of a ROS 1 or ROS 2 bag (MCAP or SQLite) into arrays, with the library rosbags.

A message's time is its ``header.stamp`` or, with ``stamp = "bag"``, the time the bag received it [ns]. Each
topic's messages are sorted by that time. Errors name the bag, the topic and the field.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servotau.apps.bag_mapping import IMU, JOINT_STATE, WRENCH, BagMapping, Topic
from servotau.errors import ConfigError


@dataclass(frozen=True, eq=False)
class TopicData:
    """One topic's messages: ``stamps`` [ns] (n,), and per field an (n, k) array.

    JointState: ``position`` [rad], ``velocity`` [rad/s], ``effort`` [N m], columns in ``joints`` order (NaN where
    a message left a field empty); Imu: ``gyro`` [rad/s], ``acc`` [m/s^2]; WrenchStamped: ``wrench`` (fx, fy, fz
    [N], tx, ty, tz [N m]).
    """

    stamps: np.ndarray
    values: dict[str, np.ndarray]
    joints: tuple[str, ...] = ()


def _stamp(msg, received: int, how: str) -> int:
    if how == "bag":
        return int(received)
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def _joint_rows(bag: Path, t: Topic, msgs: list, joints: tuple[str, ...] | None, wanted: tuple[str, ...],
                ) -> tuple[tuple[str, ...], dict[str, np.ndarray]]:
    """Arrays of the JointState fields ``wanted`` in the order ``joints`` (default: the first message's names)."""
    joints = tuple(msgs[0].name) if joints is None else joints
    out = {f: np.full((len(msgs), len(joints)), np.nan) for f in wanted}
    for i, m in enumerate(msgs):
        index = {n: k for k, n in enumerate(m.name)}
        missing = [j for j in joints if j not in index]
        if missing:
            raise ConfigError(f"{bag}: topic {t.topic} (mapping field '{t.field}'), message {i}: joint "
                              f"'{missing[0]}' is not in the message: expected it among its names {list(m.name)}")
        cols = np.array([index[j] for j in joints])
        for f in wanted:
            arr = np.asarray(getattr(m, f), dtype=float)
            if len(arr) == len(m.name):
                out[f][i] = arr[cols]
            elif len(arr) and f == "position":
                raise ConfigError(f"{bag}: topic {t.topic}, message {i}: field 'position' has {len(arr)} values for "
                                  f"{len(m.name)} names: expected one per name")
    return joints, out


def read_bag(bag: str | Path, mapping: BagMapping, joints: tuple[str, ...] | None = None) -> dict[str, TopicData]:
    """Every mapped topic of ``bag``, keyed by topic name. ``joints``: the bag joint names to read (default: those of
    the first joint_state message); each must be in every JointState message of the mapped topics."""
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    bag = Path(bag)
    if not bag.exists():
        raise ConfigError(f"{bag}: bag not found: expected a ROS 1 .bag file or a ROS 2 bag folder (MCAP or SQLite)")
    try:
        reader = AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except (AnyReaderError, OSError, ValueError) as exc:
        raise ConfigError(f"{bag}: not a readable ROS bag ({exc}): expected a ROS 1 .bag file or a ROS 2 bag "
                          "folder (MCAP or SQLite)") from exc
    try:
        by_topic = {c.topic: c for c in reader.connections}
        conns = []
        for t in mapping.topics():
            conn = by_topic.get(t.topic)
            if conn is None:
                raise ConfigError(f"{mapping.file}: field '{t.field}' = {t.topic!r}: topic not in {bag}: expected "
                                  f"one of {sorted(by_topic)}")
            got = conn.msgtype if "/msg/" in conn.msgtype else conn.msgtype.replace("/", "/msg/", 1)  # ROS 1 names
            if got != t.msgtype:
                raise ConfigError(f"{bag}: topic {t.topic} (mapping field '{t.field}') carries {conn.msgtype}: "
                                  f"expected {t.msgtype}")
            conns.append(conn)
        msgs: dict[str, list] = {t.topic: [] for t in mapping.topics()}
        stamps: dict[str, list[int]] = {t.topic: [] for t in mapping.topics()}
        for conn, received, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            msgs[conn.topic].append(msg)
            stamps[conn.topic].append(_stamp(msg, received, mapping.stamp))
    finally:
        reader.close()
    out = {}
    js_fields = ("position",) + (("velocity",) if mapping.velocity else ()) + (("effort",) if mapping.effort else ())
    for t in mapping.topics():
        if not msgs[t.topic]:
            raise ConfigError(f"{bag}: topic {t.topic} (mapping field '{t.field}') has no message: expected at "
                              "least one")
        order = np.argsort(np.asarray(stamps[t.topic]), kind="stable")
        ms = [msgs[t.topic][i] for i in order]
        st = np.asarray(stamps[t.topic], dtype=np.int64)[order]
        if t.msgtype == JOINT_STATE:
            wanted = js_fields if t is mapping.joint_state else ("position",)
            names, values = _joint_rows(bag, t, ms, joints, wanted)
            joints = joints or names
            out[t.topic] = TopicData(st, values, names)
        elif t.msgtype == IMU:
            gyro = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for m in ms])
            acc = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for m in ms])
            out[t.topic] = TopicData(st, {"gyro": gyro, "acc": acc})
        elif t.msgtype == WRENCH:
            w = np.array([[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z, m.wrench.torque.x,
                           m.wrench.torque.y, m.wrench.torque.z] for m in ms])
            out[t.topic] = TopicData(st, {"wrench": w})
    return out
