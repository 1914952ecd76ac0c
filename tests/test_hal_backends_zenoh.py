"""The controller side over Zenoh: read timeouts, closing under a read, malformed frames, real-time draining."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from support.hal import endpoint, free_port, robot_server

from servotau.errors import HalError, HalTimeoutError
from servotau.hal import MalformedMessage, ZenohBackend, keys
from servotau.hal.robot.claim import ClaimTable, claim_key
from servotau.hal.wire.protocol import HEADER_SIZE, encode_frame, info_to_json
from servotau.hal.wire.session import Session, zenoh_config
from servotau.simrobot.fake import FakeRobot

FRAME_TIMEOUT = 5.0  # [s] a safety net: the robot-time test must not fail on a descheduled robot process


def test_read_times_out_when_no_new_frame_comes(fake_zenoh):
    """Lock-step robot left without a command sends no new frame: read raises HalTimeoutError, not hangs."""
    b = fake_zenoh
    first = b.read()
    t0 = time.monotonic()
    with pytest.raises(HalTimeoutError, match=f"no frame from robot \"fake\" within 0.1 s after frame {first.seq}"):
        b.read(timeout=0.1)
    waited = time.monotonic() - t0
    assert 0.1 <= waited < 1.0  # the alarm thread woke the blocked read (its channel has no timeout)
    b.write({"J00": float(first.q[0])})  # the link still works afterwards
    assert b.read().seq == first.seq + 1


def test_close_unblocks_a_read_in_another_thread(fake_server):
    """close() from another thread ends a blocked read at once with a HalError that says the backend is closed."""
    errors: list[BaseException] = []
    b = ZenohBackend("fake", connect=[endpoint(fake_server)])
    b.read()

    def blocked_read() -> None:
        try:
            b.read(timeout=30.0)
        except BaseException as exc:  # noqa: BLE001 - the test inspects it
            errors.append(exc)

    reader = threading.Thread(target=blocked_read)
    reader.start()
    time.sleep(0.2)
    t0 = time.monotonic()
    b.close()
    reader.join(5.0)
    assert not reader.is_alive() and time.monotonic() - t0 < 5.0
    assert len(errors) == 1 and isinstance(errors[0], HalError) and "closed" in str(errors[0])


def test_realtime_read_returns_the_newest_frame_and_counts_the_skipped(tmp_path):
    """Real-time robot: frames queued while the controller was busy are skipped, the newest is returned."""
    port = free_port()
    with robot_server(tmp_path, port, clock="realtime"), \
            ZenohBackend("fake", connect=[endpoint(port)], frame_timeout=FRAME_TIMEOUT) as b:
        f0 = b.read()
        while b.status()["seq"] < f0.seq + 50:  # the robot steps 50 ticks while the controller is busy
            time.sleep(0.01)
        f1 = b.read()
        assert f1.seq - f0.seq >= 10 and b.frames_skipped >= 9
        assert b.read().seq > f1.seq


class _FramePeer:
    """A minimal robot peer inside the test: liveliness token, info and claim queryables, frames published on
    demand."""

    def __init__(self, port: int):
        self.robot = FakeRobot(name="peer")
        k = keys("peer")
        self.session = s = Session(zenoh_config(listen=[endpoint(port)]))
        s.keep(s.z.declare_queryable(k.info, lambda q: q.reply(k.info, info_to_json(self.robot.info))))
        claims = ClaimTable()
        s.keep(s.z.declare_queryable(claim_key(k.prefix), lambda q: q.reply(
            claim_key(k.prefix), claims.handle(q.payload.to_bytes(), {}, None, time.monotonic())[0])))
        self.pub = s.keep(s.z.declare_publisher(k.frame))
        s.keep(s.z.liveliness().declare_token(k.alive_robot))
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._republish_first_frame)
        self.thread.start()

    def _republish_first_frame(self) -> None:  # until the backend has connected
        while not self.stop.wait(0.01):
            self.pub.put(encode_frame(self.robot.read()))

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.session.close()


def test_a_malformed_frame_fails_this_and_every_later_read():
    """A frame that fails validation is never returned: read raises MalformedMessage naming the robot, then again."""
    port = free_port()
    peer = _FramePeer(port)
    try:
        with ZenohBackend("peer", connect=[endpoint(port)], truth=False) as b:
            peer.stop.set()
            peer.thread.join()
            frame = peer.robot.read()
            bad = bytearray(encode_frame(frame))
            bad[8:16] = (frame.seq + 1).to_bytes(8, "little")  # a newer frame...
            bad[HEADER_SIZE:HEADER_SIZE + 8] = np.float64(np.nan).tobytes()  # ...whose first encoder reads NaN
            peer.pub.put(bytes(bad))
            expected = 'robot "peer" sent a malformed frame: frame 1: joint "J00" reads nan'
            for _ in range(2):
                with pytest.raises(MalformedMessage, match=expected):
                    b.read(timeout=2.0)
    finally:
        peer.close()


def test_the_first_frame_has_its_ground_truth(fake_zenoh):
    """The robot published frame 0 and its truth before this controller subscribed: it sends frame 0's truth again
    once somebody subscribes and with every republished frame, so the controller's first logged truth row is valid
    (not NaN)."""
    b = fake_zenoh
    f = b.read()
    b.write({})
    truth = b.ground_truth(wait=1.0)
    assert f.seq == 0 and truth is not None and truth.seq == 0 and np.isfinite(truth.q).all()
    f = b.read()
    b.write({})
    assert b.ground_truth(wait=1.0).seq == f.seq == 1
