"""``servotau log convert BAG --map mapping.toml -o log.parquet``: a ROS bag as servotau's log.

Reads a ROS 1 bag or a ROS 2 bag (MCAP or SQLite) with the library rosbags and writes the log that
``servotau model`` and ``servotau identify fit`` read (hal/log.py): one row per message of the joint_state
topic (q/<joint>, the joints in the model's order); the other topics held at their latest message at or
before the row (q_des/<joint>, imu/..., ft/...), their status ``stale`` when that message is older than 1.5
periods, ``invalid`` when the topic is not mapped. Rows before every mapped topic has sent a message are
dropped (counted). ``t`` starts at 0 at the first row; the bag's time of that row is kept in the metadata
(``bag.start_ns``). The mapping file: servotau/apps/bag_mapping.py.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servotau.apps.bag_mapping import BagMapping, load_mapping
from servotau.apps.bag_read import read_bag
from servotau.errors import ConfigError

STALE_PERIODS = 1.5  # a held message older than this many periods is stale
HELP = """Convert a ROS 1 bag or a ROS 2 bag (MCAP or SQLite) into servotau's log (Parquet), which
servotau model and servotau identify fit read.

One row per message of the joint_state topic (sensor_msgs/JointState: q/<joint> [rad]); the joint_command
topic gives q_des/<joint> [rad], the imu topic (sensor_msgs/Imu) imu/gyro_x.. [rad/s] and imu/acc_x.. [m/s^2],
each ft.<sensor> topic (geometry_msgs/WrenchStamped) ft/<sensor>/fx..tz [N, N m], each held at its latest
message at or before the row (status stale when older than 1.5 periods; sensors not mapped are NaN, status
invalid). Rows before every mapped topic has sent a message are dropped. t [s] starts at 0.

Mapping file (TOML):
  [robot]          name, model ("hrp2" or an MJCF file), period [s], stamp ("header" or "bag")
  [joint_state]    topic, velocity = true|false (est/dq), effort = true|false (est/tau)
  [joint_command]  topic
  [imu]            topic
  [ft.right_ankle] topic      (sensors: right_ankle, left_ankle, right_wrist, left_wrist)
  [joints]         bag_name = "HAL_NAME"
"""


@dataclass(frozen=True)
class ConvertResult:
    """What a conversion wrote: rows, rows dropped at the start, robot time covered [s], joints, notes."""

    path: Path
    rows: int
    dropped: int
    seconds: float
    joints: tuple[str, ...]
    notes: tuple[str, ...]


def _model(mapping: BagMapping) -> Path:
    from servotau.description import MODEL_PATH

    if mapping.model == "hrp2":
        return Path(MODEL_PATH)
    p = Path(mapping.model)
    p = p if p.is_absolute() else Path(mapping.file).parent / p
    if not p.exists():
        raise ConfigError(f"{mapping.file}: field 'robot.model' = {mapping.model!r}: file not found: expected an MJCF "
                          "file (relative to the mapping file) or \"hrp2\"")
    return p


def _limits(model: Path, joints: tuple[str, ...], mapping: BagMapping) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """[rad] joint limits from the model (+-inf where a joint is not limited) and each joint's index in the model;
    every joint must be in the model."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(model))
    names = {m.joint(i).name: i for i in range(m.njnt)}
    unknown = [j for j in joints if j not in names]
    if unknown:
        raise ConfigError(f"{mapping.file}: joint '{unknown[0]}' (from topic {mapping.joint_state.topic}, renamed by "
                          f"[joints]) is not in the model {model}: expected one of {sorted(names)}; rename it in the "
                          "mapping's [joints] table")
    lo, hi = np.full(len(joints), -np.inf), np.full(len(joints), np.inf)
    for k, j in enumerate(joints):
        i = names[j]
        if m.jnt_limited[i]:
            lo[k], hi[k] = m.jnt_range[i]
    return lo, hi, [names[j] for j in joints]


def _held(stamps: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Index of the latest message at or before each row stamp (-1: none yet)."""
    return np.searchsorted(stamps, rows, side="right") - 1


def convert_bag(bag: str | Path, mapping_path: str | Path, out: str | Path) -> ConvertResult:
    """Convert ``bag`` by the mapping file into the Parquet log ``out`` (module doc)."""
    from servotau.hal.log import LogWriter
    from servotau.hal.types import FT_SENSOR_NAMES, STATUS_INVALID, STATUS_OK, STATUS_STALE, RobotInfo, SensorFrame

    mapping = load_mapping(mapping_path)
    model = _model(mapping)
    data = read_bag(bag, mapping)
    js = data[mapping.joint_state.topic]
    joints = tuple(mapping.hal_name(j) for j in js.joints)
    _, _, index = _limits(model, joints, mapping)
    order = np.argsort(index, kind="stable")  # the log's joints in the model's order
    joints = tuple(joints[k] for k in order)
    q_min, q_max, _ = _limits(model, joints, mapping)
    for t in mapping.topics():
        if data[t.topic].joints:
            data[t.topic].values.update({f: v[:, order] for f, v in data[t.topic].values.items()})
    rows = js.stamps
    held = {t.topic: _held(data[t.topic].stamps, rows) for t in mapping.topics() if t is not mapping.joint_state}
    first = max([int(np.argmax(i >= 0)) if np.any(i >= 0) else len(rows) for i in held.values()], default=0)
    if first >= len(rows) - 1:
        raise ConfigError(f"{bag}: fewer than 2 messages of {mapping.joint_state.topic} after every mapped topic "
                          f"has sent one: expected the topics to overlap in time")
    period = mapping.period or float(np.median(np.diff(rows[first:]))) * 1e-9
    if not period > 0:
        raise ConfigError(f"{bag}: topic {mapping.joint_state.topic}: its messages share one stamp: expected "
                          "increasing stamps, or set robot.period and robot.stamp = \"bag\"")
    info = RobotInfo(name=mapping.name, joint_names=joints, q_min=q_min, q_max=q_max, period=period,
                     model_path=str(model))
    extra = [f"est/dq/{j}" for j in joints] * mapping.velocity + [f"est/tau/{j}" for j in joints] * mapping.effort
    stale_ns = STALE_PERIODS * period * 1e9
    n, nft = len(rows), len(FT_SENSOR_NAMES)

    def sample(topic: str, key: str, width: int) -> tuple[np.ndarray, np.ndarray]:
        """Held values (n, width) and status (n,) of a topic's field."""
        idx = held[topic]
        values = data[topic].values[key][np.maximum(idx, 0)]
        age = rows - data[topic].stamps[np.maximum(idx, 0)]
        status = np.where(age > stale_ns, STATUS_STALE, STATUS_OK).astype(np.uint8)
        status[~np.isfinite(values).all(axis=1)] = STATUS_INVALID
        return values.reshape(n, width), status

    nan3 = np.full((n, 3), np.nan)
    gyro, acc, imu_status = nan3, nan3, np.full(n, STATUS_INVALID, dtype=np.uint8)
    if mapping.imu is not None:
        gyro, imu_status = sample(mapping.imu.topic, "gyro", 3)
        acc = data[mapping.imu.topic].values["acc"][np.maximum(held[mapping.imu.topic], 0)]
        imu_status[(imu_status == STATUS_OK) & ~np.isfinite(acc).all(axis=1)] = STATUS_INVALID
    wrenches = np.full((n, nft, 6), np.nan)
    ft_status = np.full((n, nft), STATUS_INVALID, dtype=np.uint8)
    for s, t in mapping.ft.items():
        k = FT_SENSOR_NAMES.index(s)
        wrenches[:, k], ft_status[:, k] = sample(t.topic, "wrench", 6)
    q_des, quiet = None, 0
    if mapping.joint_command is not None:
        idx = np.maximum(held[mapping.joint_command.topic], 0)
        q_des = data[mapping.joint_command.topic].values["position"][idx].copy()
        stale = rows - data[mapping.joint_command.topic].stamps[idx] > stale_ns  # the topic went quiet: no command,
        q_des[stale] = np.nan  # not an old one
        quiet = int(stale[first:].sum())
    q = js.values["position"]
    enc_status = np.where(np.isfinite(q).all(axis=1), STATUS_OK, STATUS_INVALID).astype(np.uint8)
    status = np.column_stack([enc_status, imu_status, ft_status])  # STATUS_NAMES order
    meta = {"source": "servotau log convert", "bag": str(bag), "bag.mapping": str(mapping.file),
            "bag.start_ns": str(int(rows[first]))}
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with LogWriter(out, info, truth=False, extra=extra, metadata=meta, background=False, chunk_rows=10000) as w:
        for r in range(first, n):
            frame = SensorFrame(time=(rows[r] - rows[first]) * 1e-9, seq=r - first, q=q[r],
                                imu_angular_velocity=gyro[r], imu_linear_acceleration=acc[r], wrenches=wrenches[r],
                                status=status[r])
            ex = {}
            if mapping.velocity:
                ex["est/dq"] = js.values["velocity"][r]
            if mapping.effort:
                ex["est/tau"] = js.values["effort"][r]
            w.append(frame, None if q_des is None else q_des[r], None, ex or None)
    notes = []
    if first:
        notes.append(f"{first} rows before every mapped topic had sent a message were dropped")
    missing = [s for s in FT_SENSOR_NAMES if s not in mapping.ft] + (["imu"] if mapping.imu is None else [])
    if missing:
        notes.append(f"not mapped (NaN, status invalid): {', '.join(missing)}")
    if mapping.joint_command is None:
        notes.append("no joint_command topic: q_des/<joint> is NaN (identification needs the commanded angles)")
    stale = int(np.sum(status[first:] == STATUS_STALE))
    if stale:
        notes.append(f"{stale} sensor readings held longer than {STALE_PERIODS:g} periods (status stale)")
    if quiet:
        notes.append(f"{quiet} rows without a command newer than {STALE_PERIODS:g} periods on "
                     f"{mapping.joint_command.topic}: q_des is NaN there (the workbench drops those rows)")
    return ConvertResult(out, n - first, first, float((rows[-1] - rows[first]) * 1e-9 + period), joints, tuple(notes))


def register(sub) -> None:
    p = sub.add_parser("log", help="servotau logs: convert a ROS bag into one",
                       description="Logs in servotau's format (Parquet, hal/log.py).")
    cmds = p.add_subparsers(dest="log_command", required=True, metavar="COMMAND")
    c = cmds.add_parser("convert", help="a ROS 1 or ROS 2 bag (MCAP or SQLite) as a servotau log",
                        description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    c.add_argument("bag", help="the .bag file (ROS 1) or the bag folder (ROS 2)")
    c.add_argument("--map", required=True, metavar="TOML", help="mapping of topics to log columns (above)")
    c.add_argument("-o", "--out", required=True, help="the Parquet log to write")
    c.set_defaults(func=main)


def main(args) -> int:
    r = convert_bag(args.bag, args.map, args.out)
    print(f"wrote {r.path}: {r.rows} rows, {r.seconds:.3f} s, {len(r.joints)} joints")
    for note in r.notes:
        print(f"note: {note}")
    return 0
