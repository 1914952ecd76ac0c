"""Command validation on the robot side (docs/protocol.md "Validation"): header fields, the frame a command
answers (future, time, replay, age, stale), each rejection counted by reason and never applied."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from servotau.hal import InProcessBackend, MalformedMessage, SafetyConfig
from servotau.hal.robot.gate import STALE, TAKE, CommandGate
from servotau.hal.wire.protocol import (
    HEADER,
    MAGIC,
    PROTOCOL_VERSION,
    MsgType,
    decode_command,
    encode_command,
    reject_reason,
)
from servotau.simrobot.fake import FakeRobot

INFO = FakeRobot().info
NAMES = INFO.joint_names
NQ = INFO.nq


def command(seq=0, time=0.0, q=None, flags=0, n_joints=NQ, n_ft=0, n_values=None, version=PROTOCOL_VERSION,
            mtype=MsgType.COMMAND, magic=MAGIC) -> bytes:
    """A command message with any header field set by hand."""
    q = np.zeros(NQ) if q is None else np.asarray(q, dtype=float)
    n_values = q.size if n_values is None else n_values
    return HEADER.pack(magic, version, mtype, flags, seq, time, n_joints, n_ft, n_values) + q.tobytes()


@pytest.mark.parametrize(("buf", "reason"), [
    (command(flags=0xFFFF), "flags"),
    (command(flags=2), "flags"),  # 1 is COMMAND_HOLD
    (command(version=2), "version"),
    (command(magic=b"XXXX"), "header"),
    (command(mtype=MsgType.FRAME), "header"),
    (command()[:20], "header"),
    (command(time=float("nan")), "time"),
    (command(time=float("inf")), "time"),
    (command(n_joints=NQ - 1), "counts"),
    (command(n_ft=1), "counts"),
    (command(n_values=NQ + 1), "counts"),
    (command() + b"\0", "counts"),
    (command(q=np.r_[np.zeros(NQ - 1), np.nan]), "values"),
])
def test_header_fields_are_validated_with_a_reason(buf, reason):
    with pytest.raises(MalformedMessage) as exc:
        decode_command(buf, NAMES)
    assert reject_reason(exc.value) == reason
    decode_command(command(), NAMES)  # the same, well-formed, is taken


def test_inprocess_receive_rejects_each_field_and_applies_nothing():
    """Over the in-process path (the server's checks): wrong time, wrong flags, a future frame, a replay are
    rejected with their reason; an older frame is stale; none moves the robot."""
    robot = FakeRobot()
    with InProcessBackend(robot) as b:
        f = b.read()
        q = f.q + 0.001
        assert b.receive(command(f.seq, f.time + 1e-3, q)) == "time"
        assert b.receive(command(f.seq, f.time, q, flags=0xFFFF)) == "flags"
        assert b.receive(command(f.seq + 1, f.time, q)) == "future"
        assert robot.applied == []
        assert b.receive(encode_command(f.seq, f.time, q)) == TAKE
        assert len(robot.applied) == 1
        for _ in range(100):
            assert b.receive(encode_command(f.seq, f.time, q)) == "replay"
        g = b.read()
        assert b.receive(encode_command(g.seq, g.time, q)) == TAKE
        assert b.receive(encode_command(f.seq - 1 if f.seq else 0, f.time, q)) in ("replay", STALE)
        st = b.status()
    assert len(robot.applied) == 2
    assert st["rejected"]["replay"] >= 100
    assert st["rejected"]["time"] == 1 and st["rejected"]["flags"] == 1 and st["rejected"]["future"] == 1
    assert st["commands_accepted"] == 2


def test_realtime_gate_rejects_old_commands_and_replays():
    """Realtime: a command answering a frame more than max_command_age_ticks old is rejected (the issue: 1533
    ticks old, applied); a replay of the applied one is rejected, however often; an older one is stale."""
    gate = CommandGate(lockstep=False, max_age_ticks=20)
    for seq in range(2000):
        gate.published(seq, seq * 1e-3)

    def verdict(seq: int) -> str:
        return gate.check(seq, seq * 1e-3)[0]

    assert verdict(1999 - 1533) == "too_old" and verdict(1978) == "too_old"
    assert verdict(1979) == TAKE and verdict(1999) == TAKE
    assert gate.check(1999, 2.0)[0] == "time"
    assert verdict(2000) == "future"
    gate.applied(1995)
    assert all(verdict(1995) == "replay" for _ in range(100))
    assert verdict(1990) == STALE


def test_lockstep_gate_takes_the_current_frame_only():
    gate = CommandGate(lockstep=True, max_age_ticks=0)
    for seq in range(10):
        gate.published(seq, seq * 1e-3)
    assert gate.check(9, 9 * 1e-3)[0] == TAKE and gate.check(8, 8 * 1e-3)[0] == STALE
    assert gate.check(5000, 5.0)[0] == "future"
    gate.applied(9)
    assert gate.check(9, 9 * 1e-3)[0] == "replay"


def fuzz(rng: np.random.Generator, n: int, f_seq: int, f_time: float) -> list[bytes]:
    """``n`` malformed or inadmissible commands for a robot whose current frame is ``(f_seq, f_time)``."""
    good = encode_command(f_seq, f_time, np.zeros(NQ))
    out = []
    for i in range(n):
        kind = i % 8
        if kind == 0:
            p = rng.bytes(int(rng.integers(0, 600)))
        elif kind == 1:
            p = good[: int(rng.integers(0, len(good)))]
        elif kind == 2:
            p = command(f_seq, f_time, flags=int(rng.integers(1, 2**15)) << 1)  # a bit beyond COMMAND_HOLD
        elif kind == 3:
            p = command(f_seq, f_time + float(rng.uniform(1e-6, 1.0)) * rng.choice([-1, 1]))
        elif kind == 4:
            p = command(f_seq + int(rng.integers(1, 2**40)), f_time)
        elif kind == 5:
            p = good[:24] + struct.pack("<HHI", NQ, int(rng.integers(0, 4)), int(rng.integers(0, 1000))) + good[32:]
        elif kind == 6:
            q = np.zeros(NQ)
            q[int(rng.integers(NQ))] = rng.choice([np.nan, np.inf, -np.inf])
            p = encode_command(f_seq, f_time, q)
        else:  # one random byte of the header changed
            b = bytearray(good)
            k = int(rng.integers(0, 8))  # magic, version, type, flags
            b[k] = (b[k] + int(rng.integers(1, 256))) % 256
            if k == 6 and b[k] == 1:  # COMMAND_HOLD alone is a valid command
                b[k] = 3
            p = bytes(b)
        out.append(p)
    return out


def test_ten_thousand_malformed_commands_are_never_applied():
    robot = FakeRobot()
    with InProcessBackend(robot, SafetyConfig()) as b:
        f = b.read()
        verdicts = [b.receive(p) for p in fuzz(np.random.default_rng(1), 10_000, f.seq, f.time)]
        st = b.status()
    assert robot.applied == [] and TAKE not in verdicts and STALE not in verdicts
    assert st["commands_rejected"] == 10_000 and sum(st["rejected"].values()) == 10_000
    assert st["commands_accepted"] == 0 and st["state"] == "WAITING"
    assert {"header", "flags", "time", "future", "counts", "values"} <= {k for k, v in st["rejected"].items() if v}
