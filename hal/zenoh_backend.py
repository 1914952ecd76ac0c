"""Controller side of the HAL over Zenoh (the robot side is :mod:`servotau.hal.server`)."""

from __future__ import annotations

import json
import logging
import struct
import threading
import time
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import zenoh

from .backend import Backend
from .errors import HalError, HalTimeoutError, MalformedMessage, RobotLost
from .protocol import (
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
from .realtime import set_realtime_priority
from .types import SensorFrame
from .zenoh_session import DEFAULT_ENDPOINT, Session, callback, zenoh_config

if TYPE_CHECKING:
    from servotau.simrobot.truth import GroundTruth

logger = logging.getLogger(__name__)

_TRUTH_KEPT = 16  # truth messages kept, newest ticks


class ZenohBackend(Backend):
    """Talks to a robot served over Zenoh.

    A dead robot is detected by its liveliness token vanishing (a few ms for a killed process on
    loopback): :meth:`read` then raises :class:`RobotLost`; no frame within ``frame_timeout``
    raises :class:`HalTimeoutError`.

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
            zenoh's threads (:mod:`servotau.hal.realtime`); 0: ordinary scheduling.
    """

    def __init__(
        self,
        robot: str = "hrp2",
        *,
        connect: Sequence[str] = (DEFAULT_ENDPOINT,),
        listen: Sequence[str] = (),
        mode: str = "peer",
        connect_timeout: float = 10.0,
        frame_timeout: float = 0.1,
        zenoh_extra: Mapping[str, Any] | None = None,
        truth: bool = True,
        realtime_priority: int = 0,
    ):
        self.keys = keys(robot)
        self.robot_name = robot
        self.frame_timeout = frame_timeout
        self._where = ", ".join(connect or listen)
        self._cond = threading.Condition()
        self._frame: SensorFrame | None = None  # newest frame received
        self._flags = 0
        self._truths: dict[int, bytes] = {}  # seq -> truth message, the last few ticks
        self._want_truth = truth
        self._error: HalError | None = None  # raised by the next read()
        self._alive = False
        self._min_seq = -1  # read() returns only frames with a larger seq
        self.frames_received = 0
        self.frames_skipped = 0  # real-time mode: frames never returned because a newer one came
        self._joint_names: tuple[str, ...] | None = None
        set_realtime_priority(realtime_priority)  # before the session: zenoh's threads inherit it
        self._session = Session(zenoh_config(listen=listen, connect=connect, mode=mode, extra=zenoh_extra))
        try:
            first = self._connect(connect_timeout)
        except BaseException:
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
        s.keep(z.declare_subscriber(k.frame, callback(self._on_frame)))
        if self._want_truth:
            s.keep(z.declare_subscriber(k.truth, callback(self._on_truth)))
        self._pub = s.keep(z.declare_publisher(k.command, express=True,
                                               congestion_control=zenoh.CongestionControl.BLOCK,
                                               priority=zenoh.Priority.REAL_TIME))
        s.keep(z.liveliness().declare_token(k.alive_controller))
        with self._cond:
            self._cond.wait_for(lambda: self._frame is not None or self._error is not None,
                                max(deadline - time.monotonic(), 0.0))
            if self._error is not None:
                raise self._error
            if self._frame is None:
                raise HalTimeoutError(f'robot "{self.robot_name}" is alive on {self._where} but sent no frame '
                                      f"within {timeout} s")
            return self._frame

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
                    last = f"frame {self._frame.seq} (t = {self._frame.time:.3f} s)" if self._frame else "no frame"
                    self._error = RobotLost(f'robot "{self.robot_name}" lost: its liveliness token vanished '
                                            f"(robot process stopped or killed, or link down) after {last}")
                self._alive = False
            else:
                self._alive = True
            self._cond.notify_all()

    def _on_frame(self, sample: zenoh.Sample) -> None:
        try:
            frame, flags = decode_frame(sample.payload.to_bytes(), len(self._joint_names), self._joint_names)
        except MalformedMessage as exc:
            with self._cond:
                self._error = MalformedMessage(f'robot "{self.robot_name}" sent a malformed frame: {exc}')
                self._error.__cause__ = exc
                self._cond.notify_all()
            return
        with self._cond:
            if self._frame is None or frame.seq > self._frame.seq:
                if self._frame is not None and self._frame.seq > self._min_seq:
                    self.frames_skipped += 1
                self._frame, self._flags = frame, flags
                self.frames_received += 1
                self._cond.notify_all()

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

    # -- Backend -------------------------------------------------------------------------------------
    def read(self, timeout: float | None = None) -> SensorFrame:
        timeout = self.frame_timeout if timeout is None else timeout
        with self._cond:
            ok = self._cond.wait_for(
                lambda: self._error is not None or self._closed or (self._frame.seq > self._min_seq), timeout)
            if self._error is not None:
                raise self._error
            if self._closed:
                raise HalError(f"ZenohBackend of {self.robot_name} is closed: expected an open backend")
            if not ok:
                raise HalTimeoutError(f'no frame from robot "{self.robot_name}" within {timeout} s after frame '
                                      f"{self._min_seq} (robot hung or link too slow?)")
            frame = self._frame
            self._min_seq = frame.seq
        return self._returned(frame)

    def _send(self, q_des: np.ndarray, answers: SensorFrame) -> None:
        with self._cond:
            if self._error is not None:
                raise self._error
            self._min_seq = max(self._min_seq, answers.seq)
        self._pub.put(encode_command(answers.seq, answers.time, q_des))

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

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._session.close()
