"""The robot process under faults, two real processes on loopback: NaN encoders keep it up (servo off, latched)
and the operator's reset query turns it back on; in realtime, replays, old commands and bad header fields are
rejected by reason, never applied."""

from __future__ import annotations

import json

import numpy as np
import zenoh
from conftest import FRAME_TIMEOUT
from support.hal import endpoint, free_port, robot_server, robot_status

from servotau.hal import STATUS_INVALID, SafetyConfig, ZenohBackend, keys
from servotau.hal.wire.protocol import HEADER, MAGIC, PROTOCOL_VERSION, MsgType, encode_command
from servotau.hal.wire.session import Session, zenoh_config

KEYS = keys("fake")


def operator(port: int, request: dict | bytes) -> dict:
    """Send an operator request to the robot's ``.../operator`` queryable; its JSON answer."""
    payload = request if isinstance(request, bytes) else json.dumps(request).encode()
    s = Session(zenoh_config(connect=[endpoint(port)]))
    try:
        replies = list(s.z.get(KEYS.operator, payload=payload, timeout=5.0))
        return json.loads(replies[0].ok.payload.to_bytes())
    finally:
        s.close()


def test_nan_encoders_keep_the_robot_process_up_and_reset_turns_it_back_on(tmp_path):
    """NaN encoders from 0.1 s to 1.0 s of robot time while a controller commands (lock-step): the robot holds,
    publishes the frames as INVALID, cuts its servos after invalid_encoders_after, stays up, refuses a reset
    while the encoders are invalid, accepts it once they are valid, and a new controller drives it again."""
    port, end = free_port(), 1.0
    faults = [{"kind": "nan", "start": 0.1, "duration": end - 0.1}]
    with robot_server(tmp_path, port, robot_kwargs={"encoder_faults": faults},
                      safety={"invalid_encoders_after": 0.05}) as server:
        with ZenohBackend("fake", connect=[endpoint(port)], frame_timeout=FRAME_TIMEOUT) as b:
            f = b.read()
            while f.time < 0.12:  # commands the initial posture, into the fault
                b.write({})
                f = b.read()
            assert f.status[0] == STATUS_INVALID and np.isnan(f.q).all()
            st = robot_status(port, lambda st: st["state"] == "SERVO_OFF")
        assert st["state"] == "SERVO_OFF" and "encoders invalid" in st["trip_reason"], st
        assert st["commands_during_sensor_fault"] >= 1 and server.poll() is None
        early = operator(port, {"action": "reset"})
        after_early = robot_status(port, lambda st: True)
        st = robot_status(port, lambda st: st["time"] > end + 0.05)  # servos off: the robot steps on its own clock
        assert server.poll() is None and st["state"] == "SERVO_OFF"
        late = operator(port, {"action": "reset"})
        bad = operator(port, b"{nope")
        st = robot_status(port, lambda st: True)
        with ZenohBackend("fake", connect=[endpoint(port)], frame_timeout=FRAME_TIMEOUT) as b:
            for _ in range(20):
                b.read()
                b.write({})
            st2 = b.status()
    if after_early["time"] < end:  # the first reset came while the encoders were NaN (always, unless stalled)
        assert early["ok"] is False and "encoders invalid" in early["error"] and early["state"] == "SERVO_OFF"
    assert late == {"ok": True, "state": "WAITING", "error": None}
    assert bad["ok"] is False and "not JSON" in bad["error"]
    assert st["state"] == "WAITING" and st["resets"] == 1, st
    assert st2["state"] == "RUNNING" and st2["trip_reason"].startswith("encoders invalid"), st2


def test_a_reset_ends_the_claim_of_a_controller_still_running(tmp_path):
    """A robot latched SERVO_OFF by a 1 rad step (rate limits lifted so that it reaches the servos) is reset while
    its controller still runs and keeps sending that step: the reset ends the claim, so the step is rejected
    (not from the claimer) and the robot stays WAITING at its measured posture until a new claim."""
    port = free_port()
    with robot_server(tmp_path, port, safety={"max_velocity": 1e6, "max_acceleration": 1e9}) as server:
        with ZenohBackend("fake", connect=[endpoint(port)], frame_timeout=FRAME_TIMEOUT) as b:
            step = np.asarray(b.read().q) + 1.0
            b.write_array(step)
            robot_status(port, lambda st: st["state"] == "SERVO_OFF")
            answer = operator(port, {"action": "reset"})
            b.write_array(step)  # answers the frame it last read, as a controller unaware of the reset does
            st = robot_status(port, lambda st: st["commands_not_claimer"] >= 1)
        assert server.poll() is None
    assert answer["ok"] is True and answer["state"] == "WAITING", answer
    assert st["state"] == "WAITING" and st["claim_holder"] is None and st["commands_not_claimer"] == 1, st
    assert st["commands_accepted"] == 1, st


def _command(seq: int, t: float, q: np.ndarray, flags: int = 0) -> bytes:
    return HEADER.pack(MAGIC, PROTOCOL_VERSION, MsgType.COMMAND, flags, seq, t, q.size, 0, q.size) + q.tobytes()


def test_realtime_rejects_replays_old_commands_and_bad_headers(tmp_path):
    """Realtime: one command applied, then 100 copies of it with the claim's token (as a peer that read it off the
    command key would send them: rejected as replays, never re-arming the watchdog),
    a command answering a frame older than max_command_age_ticks, a wrong time field and flags 0xFFFF: each
    rejected with its reason; the robot holds after hold_after as if the copies had never come."""
    port = free_port()
    with robot_server(tmp_path, port, clock="realtime", safety={"max_command_age_ticks": 200}) as server:
        s = Session(zenoh_config(connect=[endpoint(port)]))
        try:
            pub = s.keep(s.z.declare_publisher(KEYS.command, congestion_control=zenoh.CongestionControl.BLOCK))
            with ZenohBackend("fake", connect=[endpoint(port)], frame_timeout=FRAME_TIMEOUT, truth=False) as b:
                f = b.read()
                b.write_array(f.q)  # the one applied command
                old = b.read()  # answered below, once older than max_command_age_ticks
                st = robot_status(port, lambda st: st["commands_accepted"] == 1)
                q = np.array(f.q)
                token = b._token
                for _ in range(100):
                    pub.put(encode_command(f.seq, f.time, q), attachment=token)
                robot_status(port, lambda st: st["seq"] > old.seq + 200)
                g = b.read()
                pub.put(encode_command(old.seq, old.time, q), attachment=token)  # > 200 ticks old by now
                pub.put(_command(g.seq, g.time + 0.5, q), attachment=token)
                pub.put(_command(g.seq, g.time, q, flags=0xFFFF), attachment=token)
                st = robot_status(port, lambda st: st["commands_rejected"] >= 103 and st["state"] == "HOLDING")
        finally:
            s.close()
        assert server.poll() is None
    r = st["rejected"]
    assert r["replay"] == 100 and r["too_old"] == 1 and r["time"] == 1 and r["flags"] == 1, st
    assert st["commands_accepted"] == 1 and st["state"] == "HOLDING" and "no fresh command" in st["hold_reason"]


def test_a_frozen_lockstep_robot_cuts_its_servos_after_lockstep_servo_off_after(tmp_path):
    """Lock-step, a hung controller (connected, silent) and lockstep_servo_off_after = 0.3 s set: the robot holds
    frozen, then cuts its servos once that much wall time has passed without a command (latched SERVO_OFF)."""
    port = free_port()
    with robot_server(tmp_path, port, lockstep_hold_after=0.05, lockstep_servo_off_after=0.3) as server:
        with ZenohBackend("fake", connect=[endpoint(port)], frame_timeout=FRAME_TIMEOUT, truth=False) as b:
            for _ in range(20):
                b.read()
                b.write({})
            off = robot_status(port, lambda st: st["state"] == "SERVO_OFF")
        assert server.poll() is None
    assert off["state"] == "SERVO_OFF" and off["trips"] == 1 and "servo_off_after" in off["trip_reason"], off
    assert off["holds"] == 1 and off["hold_reason"].startswith("no fresh command"), off  # held (frozen) first


def test_hung_controller_in_lockstep_holds_and_a_fresh_command_resumes(tmp_path):
    """Lock-step with the shipped watchdog (35 ms of wall time): a controller that stops commanding but stays
    connected (hung, its liveliness token still there) makes the robot hold without stepping (simulated time
    stands still: nothing moves; the frame is republished flagged HOLDING), never cut its servos; its command
    answering that frame resumes the run where it was."""
    port = free_port()
    with robot_server(tmp_path, port, lockstep_hold_after=SafetyConfig().lockstep_hold_after) as server:
        with ZenohBackend("fake", connect=[endpoint(port)], frame_timeout=FRAME_TIMEOUT, truth=False) as b:
            for _ in range(100):
                b.read()
                b.write({})
            st = robot_status(port, lambda st: st["state"] == "HOLDING")  # the controller hangs meanwhile
            st2 = robot_status(port, lambda st: st["rtt_samples"] >= 0)
            f = b.read()  # the frame the robot waits on, republished flagged HOLDING
            assert b.robot_state == "holding" and f.seq == 100
            b.write({})
            g = b.read()  # published after the resumed tick (the next stall would hold again after 35 ms)
        assert server.poll() is None
    assert st["state"] == "HOLDING" and st["hold_reason"].startswith("no fresh command"), st
    assert st["controller_alive"] and st["lockstep_frozen"] and st["trips"] == 0
    assert st["seq"] == st2["seq"] == 100 and st["time"] == st2["time"]  # frozen: not a tick while holding
    assert g.seq == 101 and b.robot_state == "running"
