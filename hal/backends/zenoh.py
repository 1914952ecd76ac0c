"""Controller side of the HAL over Zenoh (the robot side is :mod:`servotau.hal.robot.server`)."""

from __future__ import annotations

import getpass
import json
import logging
import math
import os
import socket
import struct
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
import zenoh

from servotau.config import Section, check_settings, load_dataclass, setting

from ..backend import Backend
from ..config import endpoint_list, with_override
from ..errors import HalError, HalTimeoutError, MalformedMessage, RobotLost, RobotServoOff
from ..robot.claim import claim_key, claim_request, claim_with_retry, release_request, token_key
from ..robot.realtime import set_realtime_priority
from ..types import GroundTruth, SensorFrame
from ..wire.protocol import (
    FLAG_HOLDING,
    FLAG_SERVO_OFF,
    FLAG_WAITING,
    HEADER_SIZE,
    PROTOCOL_VERSION,
    decode_frame,
    decode_truth,
    encode_command,
    info_from_json,
    keys,
)
from ..wire.security import SECURITY_KEYS, Security, check_endpoints, field_error, security_from_section
from ..wire.session import DEFAULT_ENDPOINT, Session, callback, zenoh_config

logger = logging.getLogger(__name__)

_TRUTH_KEPT = 16  # truth messages kept, newest ticks
_FRAMES_KEPT = 64  # frames buffered between two reads (a ring: the oldest are dropped)
_ALARM_POLL = 0.02  # [s] the read-timeout alarm looks at a blocked read at least this often


@dataclass(frozen=True)
class ZenohConfig:
    """The controller side's ``[hal.zenoh]`` table: the settings of :class:`ZenohBackend`."""

    robot: str = setting("hrp2")  # key expressions servotau/v1/<robot>/...
    connect: tuple[str, ...] = setting((DEFAULT_ENDPOINT,))  # the robot's endpoint, or a zenoh router's
    listen: tuple[str, ...] = setting(())
    mode: str = setting("peer", choices=("peer", "client"))
    connect_timeout: float = setting(10.0, unit="s", min=0, strict_min=True)  # wait for the robot process
    frame_timeout: float = setting(1.0, unit="s", min=0, strict_min=True)  # no frame for this long: HalTimeoutError
    truth: bool = setting(True)  # receive the simulator's ground truth (evaluation)
    realtime_priority: int = setting(0, min=0, max=99)  # SCHED_FIFO priority of the loop and zenoh's threads
    security: Security = field(default_factory=Security)  # TLS and authentication (hal/wire/security.py)

    def __post_init__(self):
        check_settings(self, HalError)


class ZenohBackend(Backend):
    """Talks to a robot served over Zenoh.

    A dead robot is detected by its liveliness token vanishing (a few ms for a killed process on
    loopback): :meth:`read` then raises :class:`RobotLost`; no frame within ``frame_timeout``
    raises :class:`HalTimeoutError`.

    At connect the backend claims the robot (one controller at a time, hal/robot/claim.py): a robot
    claimed by another controller raises :class:`~servotau.hal.errors.ClaimRefused`, a robot whose
    servos are off (latched) :class:`~servotau.hal.errors.RobotServoOff`; :meth:`close` releases it.

    Frames reach the control thread without a Python thread in between: zenoh's network thread
    queues them in a ring channel and :meth:`read` takes them out (one GIL hand-over per frame
    instead of two through a callback thread; measurements in docs/protocol.md). Whatever must
    interrupt a blocked read (robot lost, close, the read timeout) puts an empty wake-up sample on
    the frame key, delivered to this session only.

    Args:
        robot: robot name in the key expressions (``servotau/v1/<robot>/...``).
        connect: endpoints to connect to (the robot's, or a router's).
        listen: endpoints to listen on (usually none).
        mode: zenoh mode, ``peer`` or ``client`` (through a router).
        connect_timeout: [s] wait for the robot to appear and send its first frame.
        frame_timeout: [s] default :meth:`read` timeout.
        zenoh_extra: extra zenoh config entries, path -> JSON value.
        truth: subscribe to the ground truth (simulation; False saves the robot and this process
            encoding, sending and decoding it every tick).
        realtime_priority: SCHED_FIFO priority 1..99 of the calling thread (the control loop) and of
            zenoh's threads (:mod:`servotau.hal.robot.realtime`); 0: ordinary scheduling.
        security: Zenoh TLS and authentication of this side (:class:`~servotau.hal.wire.security.Security`);
            None: plain TCP, loopback only.
    """

    def __init__(
        self,
        robot: str = ZenohConfig.robot,
        *,
        connect: Sequence[str] = ZenohConfig.connect,
        listen: Sequence[str] = ZenohConfig.listen,
        mode: str = ZenohConfig.mode,
        connect_timeout: float = ZenohConfig.connect_timeout,
        frame_timeout: float = ZenohConfig.frame_timeout,
        zenoh_extra: Mapping[str, Any] | None = None,
        truth: bool = ZenohConfig.truth,
        realtime_priority: int = ZenohConfig.realtime_priority,
        security: Security | None = None,
    ):
        self.keys = keys(robot)
        self.robot_name = robot
        self.frame_timeout = frame_timeout
        self._where = ", ".join(connect or listen)
        self._cond = threading.Condition()  # guards _error, _alive, _truths (zenoh's callback threads)
        self._flags = 0
        self._truths: dict[int, bytes] = {}  # seq -> truth message, the last few ticks
        self._want_truth = truth
        self._error: HalError | None = None  # raised by every read() from now on
        self._alive = False
        self._min_seq = -1  # read() returns only frames with a larger seq
        self._read_deadline = math.inf  # time.monotonic() [s] at which the blocked read gives up
        self.frames_received = 0
        self.frames_skipped = 0  # frames never returned by read() (a newer one came first)
        self._joint_names: tuple[str, ...] | None = None
        self._closed, self._last_read = False, None  # (Backend.__init__ runs once connected)
        self._token: bytes | None = None  # the claim's token, the attachment of every command
        set_realtime_priority(realtime_priority)  # before the session: zenoh's threads inherit it
        self._session = Session(zenoh_config(listen=listen, connect=connect, mode=mode, extra=zenoh_extra,
                                             security=security))
        try:
            first = self._connect(connect_timeout)
        except BaseException:
            self._release()
            self._session.close()
            raise
        super().__init__(self.info, first)

    # -- connection ----------------------------------------------------------------------------------
    def _connect(self, timeout: float) -> SensorFrame:
        s, z, k = self._session, self._session.z, self.keys
        deadline = time.monotonic() + timeout
        s.keep(z.liveliness().declare_subscriber(k.alive_robot, callback(self._on_liveliness), history=True))
        with self._cond:
            if not self._cond.wait_for(lambda: self._alive, timeout):
                raise HalTimeoutError(f'no robot "{self.robot_name}" ({k.alive_robot}) on {self._where} within '
                                      f"{timeout} s: is the robot process (servotau sim) running there, with the "
                                      f"same robot name and protocol v{PROTOCOL_VERSION}?")
        self.info = self._query_info(max(deadline - time.monotonic(), 0.5))
        self._joint_names = self.info.joint_names
        # the claiming session's own token first: the robot sees this session go even through a router
        s.keep(z.liveliness().declare_token(token_key(k.alive_controller, str(z.zid()))))
        self._token = self._claim(max(deadline - time.monotonic(), 0.5))
        if self._want_truth:  # first: the robot then knows it is wanted before this session sees a frame
            s.keep(z.declare_subscriber(k.truth, callback(self._on_truth)))
        self._frames = s.keep(z.declare_subscriber(k.frame, zenoh.handlers.RingChannel(_FRAMES_KEPT)))
        self._pub = s.keep(z.declare_publisher(k.command, express=True,
                                               congestion_control=zenoh.CongestionControl.BLOCK,
                                               priority=zenoh.Priority.REAL_TIME))
        threading.Thread(target=self._run_alarm, name=f"hal-{self.robot_name}-read-alarm", daemon=True).start()
        frame = self._receive(max(deadline - time.monotonic(), 0.0))
        if frame is None:
            raise HalTimeoutError(f'robot "{self.robot_name}" is alive on {self._where} but sent no frame '
                                  f"within {timeout} s")
        if self._flags & FLAG_SERVO_OFF:
            raise RobotServoOff(f'robot "{self.robot_name}": robot servos are off (latched): reset it with '
                                "`servotau ctl reset`, then connect again")
        return frame

    def _claim(self, timeout: float) -> bytes:
        """Claim the robot (hal/robot/claim.py): its token, or ClaimRefused naming the holder."""
        z = self._session.z
        request = claim_request(str(z.zid()), socket.gethostname(), os.getpid(), getpass.getuser())

        def ask(t: float) -> bytes | None:
            for r in z.get(claim_key(self.keys.prefix), payload=request, timeout=t):
                if r.ok is not None:
                    return r.ok.payload.to_bytes()
            return None

        token = claim_with_retry(ask, self.robot_name, timeout)
        if token is not None:
            return token
        raise HalTimeoutError(f'robot "{self.robot_name}" did not answer the claim on {claim_key(self.keys.prefix)} '
                              f"within {timeout} s: an older robot process, or its access control does not let "
                              "this identity claim it (see [hal.server.access])")

    def _release(self) -> None:
        """Release the claim (the robot holds at once); nothing if none is held or the robot is gone."""
        token, self._token = self._token, None
        if token is None or self._session.closed:
            return
        try:
            for _ in self._session.z.get(claim_key(self.keys.prefix), payload=release_request(token), timeout=0.5):
                pass
        except Exception:  # the robot or the session is gone: the claim ends with this session anyway
            pass

    def _query_info(self, timeout: float):
        replies = list(self._session.z.get(self.keys.info, timeout=timeout))
        for r in replies:
            if r.ok is not None:
                return info_from_json(r.ok.payload.to_bytes())
        raise HalTimeoutError(f'robot "{self.robot_name}" did not answer {self.keys.info} within {timeout} s')

    # -- zenoh callbacks -----------------------------------------------------------------------------
    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        with self._cond:
            if sample.kind == zenoh.SampleKind.DELETE:
                if self._alive:
                    f = self._last_read
                    last = f"frame {f.seq} (t = {f.time:.3f} s)" if f is not None else "no frame"
                    self._error = RobotLost(f'robot "{self.robot_name}" lost: its liveliness token vanished '
                                            f"(robot process stopped or killed, or link down) after {last}")
                self._alive = False
            else:
                self._alive = True
            self._cond.notify_all()
        if sample.kind == zenoh.SampleKind.DELETE:
            self._wake()

    def _on_truth(self, sample: zenoh.Sample) -> None:
        buf = sample.payload.to_bytes()
        if len(buf) < HEADER_SIZE:
            return
        seq = struct.unpack_from("<Q", buf, 8)[0]
        with self._cond:
            self._truths[seq] = buf
            while len(self._truths) > _TRUTH_KEPT:
                del self._truths[min(self._truths)]
            self._cond.notify_all()

    # -- frames -------------------------------------------------------------------------------------
    def _wake(self) -> None:
        """Unblock a read waiting in the frame channel: an empty sample, delivered to this session only."""
        try:
            self._session.z.put(self.keys.frame, b"", allowed_destination=zenoh.Locality.SESSION_LOCAL)
        except Exception:  # session closed: the channel is closed too, which also unblocks the read
            pass

    def _run_alarm(self) -> None:
        """Read timeouts (the frame channel's recv has none): wake a read blocked past its deadline."""
        while not (self._closed or self._session.closed):
            wait = self._read_deadline - time.monotonic()
            if wait <= 0:
                self._wake()
                wait = _ALARM_POLL  # the reader takes it from here
            time.sleep(min(wait, _ALARM_POLL))

    def _check(self) -> None:
        if self._error is not None:
            raise self._error
        if self._closed:
            raise HalError(f"ZenohBackend of {self.robot_name} is closed: expected an open backend")

    def _decode(self, sample: zenoh.Sample) -> SensorFrame | None:
        """The frame in ``sample``; None for a wake-up. A malformed frame fails this and every later read."""
        buf = sample.payload.to_bytes()
        if not buf:
            return None
        try:
            frame, self._flags = decode_frame(buf, len(self._joint_names), self._joint_names)
        except MalformedMessage as exc:
            error = MalformedMessage(f'robot "{self.robot_name}" sent a malformed frame: {exc}')
            error.__cause__ = exc
            with self._cond:
                self._error = error
            raise error from exc
        self.frames_received += 1
        return frame

    def _take(self, block: bool) -> zenoh.Sample | None:
        """The next sample of the frame channel (``block``: wait for one; else None if it is empty)."""
        try:
            return self._frames.recv() if block else self._frames.try_recv()
        except Exception:  # zenoh: the channel went with the session (close() under a read)
            self._check()
            raise HalError(f"ZenohBackend of {self.robot_name}: its zenoh session closed under a read") from None

    def _receive(self, timeout: float) -> SensorFrame | None:
        """The newest frame with a seq above the last one read, waiting at most ``timeout`` [s] for one
        (None if none came). Raises the robot's loss, a malformed frame, or the backend's closing."""
        deadline = time.monotonic() + timeout
        newest: SensorFrame | None = None
        self._check()
        while True:
            sample = self._take(block=False)
            if sample is None:
                if newest is not None:
                    return newest
                self._check()
                if time.monotonic() >= deadline:
                    return None
                self._read_deadline = deadline
                try:
                    sample = self._take(block=True)  # a frame, or a wake-up from _wake
                finally:
                    self._read_deadline = math.inf
            frame = self._decode(sample)
            if frame is None or frame.seq <= self._min_seq:  # a wake-up, or a frame already answered
                continue
            if newest is not None:
                self.frames_skipped += 1
            newest = frame

    # -- Backend -------------------------------------------------------------------------------------
    def read(self, timeout: float | None = None) -> SensorFrame:
        timeout = self.frame_timeout if timeout is None else timeout
        frame = self._receive(timeout)
        if frame is None:
            raise HalTimeoutError(f'no frame from robot "{self.robot_name}" within {timeout} s after frame '
                                  f"{self._min_seq} (robot hung or link too slow?)")
        self._min_seq = frame.seq
        return self._returned(frame)

    def _send(self, q_des: np.ndarray, answers: SensorFrame) -> None:
        if self._error is not None:
            raise self._error
        self._min_seq = max(self._min_seq, answers.seq)
        self._pub.put(encode_command(answers.seq, answers.time, q_des, self.hold_requested), attachment=self._token)

    def ground_truth(self, wait: float = 0.005) -> GroundTruth | None:
        """Ground truth of the tick of the last frame read (waits up to ``wait`` [s] for it to arrive;
        before the first read: the newest); None if it did not arrive, if the robot has none, or if
        the backend was opened with ``truth=False``."""
        if not self._want_truth:
            return None
        with self._cond:
            if self._last_read is None:
                buf = self._truths[max(self._truths)] if self._truths else None
            else:
                seq = self._last_read.seq
                self._cond.wait_for(lambda: seq in self._truths or self._closed, wait)
                buf = self._truths.get(seq)
        if buf is None:
            return None
        try:
            return decode_truth(buf, self.info.nq)
        except MalformedMessage as exc:
            logger.warning("ignoring a malformed truth message: %s", exc)
            return None

    @property
    def robot_flags(self) -> int:
        """FLAG_* bits of the newest frame (robot-side firmware state)."""
        return self._flags

    @property
    def robot_state(self) -> str:
        """Robot-side firmware state from the newest frame: waiting, running, holding or servo_off."""
        f = self._flags
        return ("servo_off" if f & FLAG_SERVO_OFF else "holding" if f & FLAG_HOLDING
                else "waiting" if f & FLAG_WAITING else "running")

    def status(self, timeout: float = 1.0) -> dict:
        """The robot server's status (``.../status`` queryable): firmware state, counters, timing."""
        for r in self._session.z.get(self.keys.status, timeout=timeout):
            if r.ok is not None:
                return json.loads(r.ok.payload.to_bytes())
        raise HalTimeoutError(f'robot "{self.robot_name}" did not answer {self.keys.status} within {timeout} s')

    def declare_queryable(self, key: str, handler) -> None:
        """Answer queries on ``key`` with ``handler(query)`` (zenoh-python's callback thread) on this backend's
        session until it closes: services of the controller process, e.g. the operator's reset and release."""
        self._session.keep(self._session.z.declare_queryable(key, callback(handler)))

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._wake()
        self._release()
        self._session.close()


def from_config(hal: Section, *, port: int | None = None) -> ZenohBackend:
    """Open a :class:`ZenohBackend` from ``[hal.zenoh]`` (``port``: connect to ``tcp/127.0.0.1:<port>``
    instead of the configured endpoints); every error names the file and the field."""
    z = hal.section("zenoh", {})
    z.check_keys([f for f in ZenohConfig.__dataclass_fields__ if f != "security"] + list(SECURITY_KEYS))
    if port is not None:
        z = with_override(z, "connect", [f"tcp/127.0.0.1:{port}"], "--port")
    endpoints = {key: tuple(endpoint_list(z, key, list(getattr(ZenohConfig, key)))) for key in ("connect", "listen")}
    security = security_from_section(z, robot_side=False)
    try:
        check_endpoints(security, [*endpoints["connect"], *endpoints["listen"]], robot_side=False)
    except HalError as exc:
        raise field_error(z, "connect", exc) from None
    cfg = load_dataclass(ZenohConfig, z, ignore=SECURITY_KEYS, security=security, **endpoints)
    return ZenohBackend(**{f.name: getattr(cfg, f.name) for f in fields(cfg)})
