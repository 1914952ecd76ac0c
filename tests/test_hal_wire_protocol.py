"""Wire format: round trips, validation of every field, key expressions."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from servotau.errors import HalError
from servotau.hal import MalformedMessage, ProtocolVersionMismatch, keys
from servotau.hal.types import STATUS_INVALID, SensorFrame
from servotau.hal.wire.protocol import (
    FLAG_HOLDING,
    HEADER,
    HEADER_SIZE,
    MAGIC,
    MsgType,
    decode_command,
    decode_frame,
    decode_header,
    decode_truth,
    encode_command,
    encode_frame,
    encode_truth,
    info_from_json,
    info_to_json,
)
from servotau.simrobot.fake import FakeRobot

ROBOT = FakeRobot(seed=3)
NAMES = ROBOT.info.joint_names


def _frame(**changes) -> SensorFrame:
    f = ROBOT.read()
    d = {k: getattr(f, k) for k in ("time", "seq", "q", "imu_angular_velocity", "imu_linear_acceleration",
                                    "wrenches", "status")}
    d.update(changes)
    return SensorFrame(**d)


def test_frame_round_trip():
    """A frame survives encode/decode bit for bit, with its flags."""
    f = _frame(seq=12345678901, time=12.345)
    g, flags = decode_frame(encode_frame(f, FLAG_HOLDING), len(NAMES))
    assert flags == FLAG_HOLDING and g.seq == f.seq and g.time == f.time
    for name in ("q", "imu_angular_velocity", "imu_linear_acceleration", "wrenches", "status"):
        np.testing.assert_array_equal(getattr(g, name), getattr(f, name))
    assert g.wrenches.shape == (4, 6) and g.status.dtype == np.uint8


def test_command_and_truth_round_trip():
    """Commands carry the seq they answer; ground truth round-trips."""
    q = np.linspace(-1, 1, len(NAMES))
    c = decode_command(encode_command(41, 0.041, q), NAMES)
    assert c.seq == 41 and c.time == 0.041
    np.testing.assert_array_equal(c.q_des, q)
    t = ROBOT.ground_truth()
    u = decode_truth(encode_truth(t), len(NAMES))
    np.testing.assert_array_equal(u.to_vector(), t.to_vector())
    assert (u.seq, u.time) == (t.seq, t.time)


def test_info_json_round_trip():
    """RobotInfo survives JSON; a wrong protocol version is named."""
    info = info_from_json(info_to_json(ROBOT.info))
    assert info.joint_names == NAMES and info.period == ROBOT.info.period
    np.testing.assert_array_equal(info.q_min, ROBOT.info.q_min)
    with pytest.raises(ProtocolVersionMismatch, match="protocol 7"):
        info_from_json(info_to_json(ROBOT.info).replace('"protocol": 1', '"protocol": 7'))
    with pytest.raises(MalformedMessage, match="JSON"):
        info_from_json(b"{not json")


def _with_header(buf: bytes, **fields) -> bytes:
    names = ("magic", "version", "type", "flags", "seq", "time", "n_joints", "n_ft", "n_values")
    h = dict(zip(names, HEADER.unpack_from(buf), strict=True))
    h.update(fields)
    return HEADER.pack(*h.values()) + buf[HEADER_SIZE:]


def test_command_validation_reasons():
    """Each malformed command raises MalformedMessage with a reason naming what was expected."""
    good = encode_command(3, 0.003, np.zeros(len(NAMES)))
    cases = {
        "at least the 32-byte header": good[:10],
        "bad magic": b"XXXX" + good[4:],
        "264 bytes: expected 272": good[:-8],  # truncated
        "message type FRAME": _with_header(good, type=MsgType.FRAME),
        "command for 29 joints": encode_command(3, 0.003, np.zeros(29)),
        "declares 31 values": _with_header(good, n_values=31),
        "finite robot time": encode_command(3, float("nan"), np.zeros(len(NAMES))),
    }
    for reason, buf in cases.items():
        with pytest.raises(MalformedMessage, match=reason):
            decode_command(buf, NAMES)
    with pytest.raises(ProtocolVersionMismatch, match="version 2: expected 1"):
        decode_command(_with_header(good, version=2), NAMES)
    q = np.zeros(len(NAMES))
    q[7] = np.inf
    with pytest.raises(MalformedMessage, match='joint "J07" = inf: expected a finite angle'):
        decode_command(encode_command(3, 0.003, q), NAMES)


def test_frame_validation():
    """NaN is accepted only where the sensor status says so; bad status values are rejected."""
    q = ROBOT.read().q.copy()
    q[2] = np.nan
    with pytest.raises(MalformedMessage, match='joint "J02" reads nan with status OK'):
        decode_frame(encode_frame(_frame(q=q)), len(NAMES), NAMES)
    status = np.zeros(6, dtype=np.uint8)
    status[0] = STATUS_INVALID
    g, _ = decode_frame(encode_frame(_frame(q=q, status=status)), len(NAMES))
    assert np.isnan(g.q[2]) and not g.is_ok("encoders")
    with pytest.raises(MalformedMessage, match="status"):
        decode_frame(encode_frame(_frame(status=np.full(6, 9, dtype=np.uint8))), len(NAMES))
    with pytest.raises(MalformedMessage, match="frame has 30 joints: expected 12"):
        decode_frame(encode_frame(_frame()), 12)
    with pytest.raises(MalformedMessage, match="message type COMMAND: expected FRAME"):
        decode_frame(encode_command(0, 0.0, np.zeros(30)))


def test_header_and_errors_are_hal_errors():
    """Protocol errors are HalErrors and ValueErrors; decode_header reports the type."""
    h = decode_header(encode_command(5, 0.5, np.zeros(4)))
    assert h.type == MsgType.COMMAND and h.seq == 5 and h.n_joints == 4
    assert issubclass(MalformedMessage, HalError) and issubclass(MalformedMessage, ValueError)
    assert MAGIC == b"STAU"


def test_keys_are_namespaced_by_robot_and_version():
    """Key expressions carry the protocol version and the robot name; bad names are refused."""
    k = keys("hrp2")
    assert k.frame == "servotau/v1/hrp2/frame" and k.command == "servotau/v1/hrp2/command"
    assert k.alive_robot == "servotau/v1/hrp2/alive/robot" and k.info == "servotau/v1/hrp2/info"
    for bad in ("a/b", "x*", "", "r obot"):
        with pytest.raises(HalError):
            keys(bad)


def test_header_layout_is_32_bytes():
    """The header's struct layout is 32 bytes (the encode and decode times are measured by bench/hal.py)."""
    assert struct.calcsize("<4sBBHQdHHI") == HEADER_SIZE == 32
