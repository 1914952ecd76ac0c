"""Wire format of the HAL over Zenoh, protocol version 1 (the reference is docs/protocol.md).

Every message is a 32-byte little-endian header followed by a float64 block::

    offset size type     field
     0     4    char[4]  magic b"STAU"
     4     1    uint8    protocol version (1)
     5     1    uint8    message type: 1 frame, 2 command, 3 truth
     6     2    uint16   flags (frame: robot-side firmware state, FLAG_*; command: COMMAND_HOLD or 0; truth: 0)
     8     8    uint64   seq: tick of the frame; a command carries the seq of the frame it answers
    16     8    float64  robot time [s] (sim time in simulation, never wall clock)
    24     2    uint16   n_joints
    26     2    uint16   n_ft (frame: F/T sensors; truth: rows of the wrench block; command: 0)
    28     4    uint32   n_values: number of float64 that follow
    32   8*n_values      float64 block
    ...  2+n_ft          uint8 sensor status (frame only, STATUS_NAMES order)

Decoding validates everything and raises :class:`MalformedMessage` (or its subclass
:class:`ProtocolVersionMismatch`) with the reason, and a short reason code in its ``reason`` attribute
(:func:`reject_reason`); a malformed command is never applied.
"""

from __future__ import annotations

import functools
import json
import math
import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from ..errors import HalError, MalformedMessage, ProtocolVersionMismatch
from ..types import STATUS_SATURATED, GroundTruth, RobotInfo, SensorFrame

PROTOCOL_VERSION = 1
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"  # where the robot listens unless configured otherwise
MAGIC = b"STAU"
KEY_ROOT = "servotau"

HEADER = struct.Struct("<4sBBHQdHHI")
HEADER_SIZE = HEADER.size  # 32 [bytes]

FLAG_WAITING = 1 << 0  # no command received yet: holding the initial position
FLAG_HOLDING = 1 << 1  # watchdog: no fresh command, holding the measured position
FLAG_SERVO_OFF = 1 << 2  # servos cut (latched): no motor current
FLAG_CLAMPED = 1 << 3  # the command applied at this tick was clamped to the joint limits
FLAG_RATE_LIMITED = 1 << 4  # the command applied at this tick was bounded by the velocity/acceleration limits
FLAG_SENSOR_FAULT = 1 << 5  # the encoders are invalid or stale: holding their last valid reading

COMMAND_HOLD = 1 << 0  # command flag: the controller has tripped; the robot holds now, braking, from its own
# measurements (q_des is not applied), until a command without the flag (docs/protocol.md "State machine")
COMMAND_FLAGS = COMMAND_HOLD  # every flag bit a command may carry; any other bit: rejected ("flags")

_F8 = np.dtype("<f8")
_ROBOT_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


class MsgType(IntEnum):
    """Message type byte of the header."""

    FRAME = 1
    COMMAND = 2
    TRUTH = 3


class Header(NamedTuple):
    """Decoded message header (magic and version already checked)."""

    type: MsgType
    flags: int
    seq: int
    time: float  # [s] robot time
    n_joints: int
    n_ft: int
    n_values: int


class Command(NamedTuple):
    """A decoded command: desired angles answering frame ``seq``."""

    seq: int  # seq of the frame this command answers
    time: float  # [s] robot time of that frame
    q_des: np.ndarray  # [rad] (n_joints,) in RobotInfo.joint_names order
    hold: bool = False  # COMMAND_HOLD: the controller holds after a trip (the robot brakes and holds itself)


@dataclass(frozen=True)
class Keys:
    """Zenoh key expressions of one robot, namespaced by protocol version."""

    prefix: str  # servotau/v1/<robot>
    frame: str  # robot -> controller: SensorFrame, one per tick
    command: str  # controller -> robot: desired angles
    truth: str  # robot -> evaluation: GroundTruth (simulation only)
    info: str  # queryable: RobotInfo as JSON
    status: str  # queryable: firmware state, counters, timing as JSON
    alive_robot: str  # liveliness token of the robot process
    alive_controller: str  # liveliness token of the controller process
    operator: str  # queryable: operator requests as JSON (``{"action": "reset"}``), answered as JSON


def keys(robot: str) -> Keys:
    """Key expressions for robot ``robot`` (letters, digits, ``_ . -``)."""
    if not isinstance(robot, str) or not _ROBOT_NAME.match(robot):
        raise MalformedMessage(f"robot name {robot!r}: expected letters, digits, '_', '.' or '-' only")
    p = f"{KEY_ROOT}/v{PROTOCOL_VERSION}/{robot}"
    return Keys(p, f"{p}/frame", f"{p}/command", f"{p}/truth", f"{p}/info", f"{p}/status",
                f"{p}/alive/robot", f"{p}/alive/controller", f"{p}/operator")


# ---------------------------------------------------------------------------------------------- header

def _bad(reason: str, msg: str, cls: type[MalformedMessage] = MalformedMessage) -> MalformedMessage:
    """A decoding error with its reason code (see :func:`reject_reason`)."""
    exc = cls(msg)
    exc.reason = reason
    return exc


def reject_reason(exc: MalformedMessage) -> str:
    """Reason code of a decoding error: ``header`` (size, magic, type), ``version``, ``time`` (not finite),
    ``flags`` (a bit beyond COMMAND_FLAGS in a command), ``counts`` (joints, F/T sensors, values, length) or
    ``values`` (NaN/inf)."""
    return getattr(exc, "reason", "version" if isinstance(exc, ProtocolVersionMismatch) else "header")


def decode_header(buf: bytes, expected: MsgType | None = None) -> Header:
    """Check magic, version and type of a message and return its header."""
    h = _unpack(buf, 0 if expected is None else int(expected))
    return Header(MsgType(h[2]), *h[3:])


def _unpack(buf: bytes, expected: int) -> tuple:
    """Raw header tuple ``(magic, version, type, flags, seq, time, n_joints, n_ft, n_values)``, checked
    (``expected``: a MsgType, or 0 for any)."""
    if len(buf) < HEADER_SIZE:
        raise _bad("header", f"message of {len(buf)} bytes: expected at least the {HEADER_SIZE}-byte header")
    h = HEADER.unpack_from(buf)
    if h[0] != MAGIC or h[1] != PROTOCOL_VERSION or not (h[2] == expected or (not expected and 0 < h[2] <= 3)) \
            or not math.isfinite(h[5]):
        magic, version, mtype, _, _, t = h[:6]
        if magic != MAGIC:
            raise _bad("header", f"bad magic {magic!r}: expected {MAGIC!r} (not a servotau message)")
        if version != PROTOCOL_VERSION:
            raise _bad("version", f"protocol version {version}: expected {PROTOCOL_VERSION} (update the older peer)",
                       ProtocolVersionMismatch)
        if mtype not in set(MsgType):
            raise _bad("header", f"message type {mtype}: expected one of {[int(m) for m in MsgType]}")
        if expected and mtype != expected:
            raise _bad("header", f"message type {MsgType(mtype).name}: expected {MsgType(expected).name}")
        raise _bad("time", f"{MsgType(mtype).name} time = {t}: expected a finite robot time [s]")
    return h


def _check_size(buf: bytes, h: tuple, n_values: int, tail: int) -> None:
    size = HEADER_SIZE + 8 * n_values + tail
    if h[8] != n_values or len(buf) != size:
        what = MsgType(h[2]).name
        if h[8] != n_values:
            raise _bad("counts", f"{what} declares {h[8]} values: expected {n_values} "
                                 f"for {h[6]} joints and {h[7]} F/T sensors")
        raise _bad("counts", f"{what} of {len(buf)} bytes: expected {size}")


def _all_finite(x: np.ndarray) -> bool:
    return bool(np.isfinite(x).all())


def _joint(i: int, names: Sequence[str] | None) -> str:
    return f'joint "{names[i]}"' if names is not None else f"joint index {i}"


# ---------------------------------------------------------------------------------------------- frame

def encode_frame(frame: SensorFrame, flags: int = 0) -> bytes:
    """Serialize a :class:`SensorFrame` (``flags``: robot-side FLAG_* bits)."""
    n, n_ft = frame.q.shape[0], frame.wrenches.shape[0]
    block = np.concatenate((frame.q, frame.imu_angular_velocity, frame.imu_linear_acceleration,
                            frame.wrenches.ravel()))
    status = np.asarray(frame.status, dtype=np.uint8)
    if status.shape != (2 + n_ft,):
        raise MalformedMessage(f"frame status has shape {status.shape}: expected ({2 + n_ft},)")
    head = HEADER.pack(MAGIC, PROTOCOL_VERSION, MsgType.FRAME, flags, frame.seq, frame.time, n, n_ft, block.size)
    return head + block.astype(_F8, copy=False).tobytes() + status.tobytes()


def decode_frame(buf: bytes, n_joints: int | None = None,
                 joint_names: Sequence[str] | None = None) -> tuple[SensorFrame, int]:
    """Parse a frame message into ``(SensorFrame, flags)``; the arrays are read-only views.

    Non-finite values are accepted only in a sensor whose status is not STATUS_OK (types.py).
    """
    h = _unpack(buf, MsgType.FRAME)
    n, n_ft = h[6], h[7]
    if n_joints is not None and n != n_joints:
        raise MalformedMessage(f"frame has {n} joints: expected {n_joints}")
    n_values = n + 6 + 6 * n_ft
    _check_size(buf, h, n_values, 2 + n_ft)
    vals = np.frombuffer(buf, _F8, n_values, HEADER_SIZE)
    end = HEADER_SIZE + 8 * n_values
    if max(buf[end:], default=0) > STATUS_SATURATED:
        raise MalformedMessage(f"frame status {list(buf[end:])}: expected values in 0..{STATUS_SATURATED}")
    status = np.frombuffer(buf, np.uint8, 2 + n_ft, end)
    if not _all_finite(vals):
        groups = [(0, n, 0, "encoders")] + [(n, n + 6, 1, "imu")] + [
            (n + 6 + 6 * i, n + 12 + 6 * i, 2 + i, f"F/T sensor {i}") for i in range(n_ft)]
        for a, b, s, what in groups:
            if status[s] == 0 and not np.isfinite(vals[a:b]).all():
                bad = a + int(np.flatnonzero(~np.isfinite(vals[a:b]))[0])
                where = _joint(bad, joint_names) if s == 0 else what
                raise MalformedMessage(f"frame {h[4]}: {where} reads {vals[bad]} with status OK: "
                                       "expected finite values (or a non-OK status)")
    frame = SensorFrame(
        time=h[5],
        seq=h[4],
        q=vals[:n],
        imu_angular_velocity=vals[n : n + 3],
        imu_linear_acceleration=vals[n + 3 : n + 6],
        wrenches=vals[n + 6 :].reshape(n_ft, 6),
        status=status,
    )
    return frame, h[3]


# ---------------------------------------------------------------------------------------------- command

def encode_command(seq: int, time: float, q_des: np.ndarray, hold: bool = False) -> bytes:
    """Serialize desired angles [rad] (RobotInfo order) answering frame ``seq`` stamped ``time`` (``hold``: with
    the COMMAND_HOLD flag)."""
    q_des = np.asarray(q_des, dtype=_F8)
    flags = COMMAND_HOLD if hold else 0
    head = HEADER.pack(MAGIC, PROTOCOL_VERSION, MsgType.COMMAND, flags, seq, time, q_des.size, 0, q_des.size)
    return head + q_des.tobytes()


def decode_command(buf: bytes, joint_names: Sequence[str]) -> Command:
    """Parse and validate a command for a robot with joints ``joint_names`` (flags within COMMAND_FLAGS, counts,
    finite angles; whether its seq and time match a published frame is the robot's check, hal/robot/gate.py)."""
    h = _unpack(buf, MsgType.COMMAND)
    n = len(joint_names)
    if h[3] & ~COMMAND_FLAGS:
        raise _bad("flags", f"command flags = {h[3]:#06x}: expected 0 or {COMMAND_HOLD:#06x} (COMMAND_HOLD)")
    if h[6] != n or h[7] != 0:
        raise _bad("counts", f"command for {h[6]} joints and {h[7]} F/T sensors: expected {n} joints and 0")
    _check_size(buf, h, n, 0)
    q = np.frombuffer(buf, _F8, n, HEADER_SIZE)
    if not _all_finite(q):
        bad = int(np.flatnonzero(~np.isfinite(q))[0])
        raise _bad("values", f"command answering frame {h[4]}: {_joint(bad, joint_names)} = {q[bad]}: "
                             "expected a finite angle [rad]")
    return Command(h[4], h[5], q, bool(h[3] & COMMAND_HOLD))


# ---------------------------------------------------------------------------------------------- truth

@functools.lru_cache(maxsize=8)
def truth_layout(n_joints: int) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """``(field, shape)`` of each GroundTruth field, in the order of ``GroundTruth.to_vector``."""
    probe = GroundTruth.from_vector(0.0, 0, np.zeros(100 * n_joints + 10_000), n_joints)
    return tuple((f, np.shape(getattr(probe, f))) for f in GroundTruth.FIELDS)


def truth_size(n_joints: int) -> int:
    """Number of float64 in a truth message for ``n_joints`` joints."""
    return sum(int(np.prod(s)) for _, s in truth_layout(n_joints))


def encode_truth(truth: GroundTruth) -> bytes:
    """Serialize a GroundTruth (simulation only)."""
    vec = np.asarray(truth.to_vector(), dtype=_F8)
    n = np.shape(truth.q)[0]
    n_ft = np.shape(truth.wrenches)[0]
    head = HEADER.pack(MAGIC, PROTOCOL_VERSION, MsgType.TRUTH, 0, truth.seq, truth.time, n, n_ft, vec.size)
    return head + vec.tobytes()


def decode_truth(buf: bytes, n_joints: int) -> GroundTruth:
    """Parse and validate a truth message."""
    h = _unpack(buf, MsgType.TRUTH)
    if h[6] != n_joints:
        raise MalformedMessage(f"truth has {h[6]} joints: expected {n_joints}")
    size = truth_size(n_joints)
    _check_size(buf, h, size, 0)
    vec = np.frombuffer(buf, _F8, size, HEADER_SIZE)
    if not _all_finite(vec):
        raise MalformedMessage(f"truth {h[4]} has non-finite values: expected finite values")
    return GroundTruth.from_vector(h[5], h[4], vec, n_joints)


# ---------------------------------------------------------------------------------------------- info

def info_to_json(info: RobotInfo) -> str:
    """RobotInfo as JSON (the ``.../info`` queryable and the log metadata)."""
    return json.dumps({
        "protocol": PROTOCOL_VERSION,
        "name": info.name,
        "joint_names": list(info.joint_names),
        "q_min": [float(x) for x in info.q_min],
        "q_max": [float(x) for x in info.q_max],
        "period": info.period,
        "model_path": info.model_path,
        "ft_sensor_names": list(info.ft_sensor_names),
        "max_position_error": info.max_position_error,
        "ft_sensor_frames": list(info.ft_sensor_frames),
        "root_joint": info.root_joint,
    })


_INFO_OPTIONAL = ("ft_sensor_frames", "root_joint")  # absent from older peers and logs: RobotInfo's defaults


def info_from_json(text: str | bytes) -> RobotInfo:
    """Inverse of :func:`info_to_json`; raises MalformedMessage on any mismatch."""
    try:
        d = json.loads(text)
    except (ValueError, TypeError) as exc:
        raise MalformedMessage(f"RobotInfo is not valid JSON: {exc}") from exc
    if not isinstance(d, dict):
        raise MalformedMessage(f"RobotInfo JSON is a {type(d).__name__}: expected an object")
    if d.get("protocol") != PROTOCOL_VERSION:
        raise ProtocolVersionMismatch(f"RobotInfo of protocol {d.get('protocol')}: expected {PROTOCOL_VERSION}")
    try:
        return RobotInfo(
            name=d["name"],
            joint_names=tuple(d["joint_names"]),
            q_min=np.asarray(d["q_min"], dtype=float),
            q_max=np.asarray(d["q_max"], dtype=float),
            period=float(d["period"]),
            model_path=d["model_path"],
            ft_sensor_names=tuple(d["ft_sensor_names"]),
            max_position_error=float(d["max_position_error"]),
            **{k: (tuple(d[k]) if k == "ft_sensor_frames" else d[k]) for k in _INFO_OPTIONAL if k in d},
        )
    except KeyError as exc:
        raise MalformedMessage(f"RobotInfo JSON lacks field {exc}") from None
    except (ValueError, TypeError, HalError) as exc:
        raise MalformedMessage(f"RobotInfo JSON is invalid: {exc}") from exc
