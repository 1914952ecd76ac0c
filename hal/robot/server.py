"""Robot side of the HAL: serves a :class:`ServedRobot` over Zenoh behind the firmware safety.

Per tick k: read the sensors, publish frame k (and ground truth k), take the command, run the
firmware (:mod:`servotau.hal.robot.firmware`), step the robot. Clock modes:

- ``lockstep`` (default): wait for the command answering frame k, then step: as fast as the
  controller, deterministic. Before the first command the robot does not move and frame 0 is
  republished every ``republish_interval`` (late joiners). Without a fresh command the watchdog
  counts in wall time and holds without stepping while the controller lives (:meth:`_run_lockstep`);
  otherwise, once holding, the robot steps one tick per period of wall time.
- ``realtime``: one tick per period of wall time (1 kHz on HRP-2); the newest command wins.
- ``robot``: as realtime, but paced by the robot itself (a real robot's ``step()`` blocks until
  its next tick).

Run it as ``python -m servotau.hal --robot module:callable`` (:mod:`.cli`; see ``--help``).
"""

from __future__ import annotations

import json
import logging
import math
import signal
import threading
import time
from collections.abc import Callable

import numpy as np
import zenoh

from ..errors import MalformedMessage
from ..log import LogWriter
from ..wire.protocol import (
    PROTOCOL_VERSION,
    decode_command,
    encode_frame,
    encode_truth,
    info_to_json,
    keys,
    reject_reason,
)
from ..wire.session import Session, callback, zenoh_config
from . import operator
from .claim import ClaimTable, claim_key
from .config import CLOCKS, ServerConfig
from .firmware import LOG_EXTRA, Firmware, FirmwareState, checked_frame
from .gate import STALE, TAKE, CommandGate, PendingCommand
from .realtime import set_realtime_priority, set_timer_slack
from .served import ServedRobot

__all__ = ["CLOCKS", "LOG_EXTRA", "RobotServer", "ServerConfig", "serve"]

logger = logging.getLogger(__name__)

_RTT_WINDOW = 100_000  # last RTT samples kept for the percentiles


class RobotServer:
    """Serves one robot until :meth:`stop`, ``max_ticks`` or an error (see the module docstring)."""

    def __init__(self, robot: ServedRobot, config: ServerConfig | None = None,
                 on_ready: Callable[[], None] | None = None):
        self.robot = robot
        self.on_ready = on_ready  # called once the robot is served (token declared)
        self.config = config or ServerConfig()
        self.info = robot.info
        self.keys = keys(self.config.robot or self.info.name)
        self.lockstep = self.config.clock == "lockstep"
        safety = self.config.safety.for_lockstep() if self.lockstep else self.config.safety
        self.firmware = Firmware(self.info, safety)
        self.gate = CommandGate(self.lockstep, safety.max_command_age_ticks)
        # Everything below is guarded by _cond; a tick runs in the thread that triggers it: the command
        # callback (zenoh's network thread) in lock-step, no thread hand-off on the critical path; else
        # the run() thread.
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._serving = False
        self._error: BaseException | None = None  # raised by run() (a tick failed in the callback thread)
        self._log: LogWriter | None = None
        self._frame = None  # current frame: published, not stepped yet
        self._truth = None
        self._servo_off_sent = False
        self._pending = PendingCommand()  # real time: the command to apply at the end of the tick
        self._published = -1  # seq of the last published frame
        self._t_published = math.nan  # when it was (last) published, time.monotonic() [s]
        self._controller_lost = False
        self._frozen = False  # lock-step: holding for a hung controller without stepping (_run_lockstep)
        self.claims = ClaimTable()  # who controls the robot (hal/robot/claim.py), guarded by _cond
        self._tokens: set[str] = set()  # zids whose alive/controller/<zid> token is alive, guarded by _cond
        self._rtt = np.zeros(_RTT_WINDOW)
        self._n_rtt = 0
        self.ticks = 0
        self.late_ticks = 0
        self._session: Session | None = None

    # -- zenoh callbacks (zenoh-python's callback thread; commands: zenoh's network thread) ---------
    def _on_command(self, sample: zenoh.Sample) -> None:
        t = time.monotonic()
        buf = sample.payload.to_bytes()
        try:
            seq, t_cmd, q_des, hold = decode_command(buf, self.info.joint_names)
        except MalformedMessage as exc:
            with self._cond:
                self.firmware.reject(reject_reason(exc), str(exc))
            return
        with self._cond:
            if not self.claims.allows(sample.attachment.to_bytes() if sample.attachment is not None else None):
                self.firmware.reject("not_claimer", "without the token of the claim (hal/robot/claim.py)")
                return
            verdict, why = self.gate.check(seq, t_cmd)  # docs/protocol.md "Validation"
            if verdict not in (TAKE, STALE):
                self.firmware.reject(verdict, why)
                return
            if seq == self._published and verdict == TAKE:  # round trip: frame published -> its command received
                self._rtt[self._n_rtt % _RTT_WINDOW] = t - self._t_published
                self._n_rtt += 1
            if not self._serving:
                return
            if verdict == STALE:
                self.firmware.stale()
            elif not self.lockstep:  # real time: the newest command wins, applied at the end of the tick
                if not self._pending.offer(q_des, t, seq, hold):
                    self.firmware.stale()
            else:  # lock-step: the command answering the current frame
                self.firmware.accept(q_des, t, hold)
                self.gate.applied(seq)
                if self._frozen and self._commanded():  # resumed: the watchdog re-arms
                    self._frozen = False
                    self._cond.notify_all()
                try:
                    self._tick(time.monotonic())
                except BaseException as exc:  # reported by run()
                    self._error = exc
                    self._stop.set()
                    self._cond.notify_all()

    def _on_controller_liveliness(self, sample: zenoh.Sample) -> None:
        """A claiming session's own token ``.../alive/controller/<zid>`` came or vanished (through a router)."""
        zid = str(sample.key_expr).rsplit("/", 1)[-1]
        if sample.kind == zenoh.SampleKind.DELETE:
            with self._cond:
                self._tokens.discard(zid)
            self._session_gone(zid, "its liveliness token vanished")
        else:
            with self._cond:
                self._tokens.add(zid)

    def _on_transport(self, event: zenoh.TransportEvent) -> None:
        """A peer's transport to the robot closed: if it held the claim, the controller is gone."""
        if event.kind == zenoh.SampleKind.DELETE:
            self._session_gone(str(event.transport.zid), "its session's transport closed")

    def _session_gone(self, zid: str, how: str) -> None:
        with self._cond:
            holder = self.claims.holder
            if self.claims.session_gone(zid):
                logger.warning("%s: controller %s lost: %s", self.info.name, holder.describe(), how)
                self._controller_lost = True
                self._cond.notify_all()

    def _on_claim(self, query: zenoh.Query) -> None:
        """Claim or release (hal/robot/claim.py); the robot holds at once when a claim ends."""
        links = {}
        try:
            for link in self._session.z.info.links():
                links[str(link.zid)] = link.auth_identifier
            for tr in self._session.z.info.transports():
                links.setdefault(str(tr.zid), None)
        except Exception:  # session closing
            pass
        payload = query.payload.to_bytes() if query.payload is not None else b""
        with self._cond:
            reply, event = self.claims.handle(payload, links, self._tokens, time.monotonic())
            if event == "released":
                self._controller_lost = True
                self._cond.notify_all()
            if event is not None:
                holder = self.claims.holder
                logger.info("%s: claim %s%s", self.info.name, event, f" to {holder.describe()}" if holder else "")
        query.reply(str(query.key_expr), reply)

    def _on_truth_matching(self, status: zenoh.MatchingStatus) -> None:
        """Somebody subscribes to the truth now (or nobody any more): the truth of the frame on the wire goes out
        at once, so that a controller that connects has the truth of its first frame."""
        self._truth_wanted = status.matching
        if status.matching:
            with self._cond:
                if self._serving:
                    self._put_truth()

    def _on_query(self, query: zenoh.Query) -> None:
        key = str(query.key_expr)
        if key == self.keys.operator:
            body = self._operator(query.payload.to_bytes() if query.payload is not None else None)
        else:
            body = info_to_json(self.info) if key == self.keys.info else json.dumps(self.status())
        query.reply(key, body)

    def _operator(self, payload: bytes | None) -> str:
        """Answer an operator request (hal/robot/operator.py); a reset republishes the frame with its state and
        ends the claim: a controller still running would otherwise drive the robot back to where it tripped, so
        the next motion needs a new claim."""
        with self._cond:
            if self._frame is None:
                return json.dumps({"ok": False, "state": self.firmware.state.name, "error": "not serving yet"})
            body, did = operator.answer(self.firmware, self.robot, self._frame, payload)
            logger.warning("%s: operator request %r: %s", self.info.name, payload[:200] if payload else payload, body)
            if did:
                holder = self.claims.release()
                if holder is not None:
                    logger.warning("%s: the reset ends the claim of %s", self.info.name, holder.describe())
                self._servo_off_sent = False
                self._pending.clear()
                if self._serving:
                    self._publish(truth=False)
                self._cond.notify_all()
            return body

    # -- public ------------------------------------------------------------------------------------
    def status(self) -> dict:
        """Firmware state and counters, clock mode, timing (``process_cpu_s``: the process's CPU time so far
        [s]): JSON-ready (also on ``.../status``)."""
        n = min(self._n_rtt, _RTT_WINDOW)
        rtt = self._rtt[:n] * 1e6
        with self._cond:
            fw = self.firmware.status()
        return {
            "robot": self.info.name, "protocol": PROTOCOL_VERSION, "clock": self.config.clock,
            "seq": self._published, "time": self._frame.time if self._frame is not None else None,
            "ticks": self.ticks, "late_ticks": self.late_ticks,
            "controller_alive": self.claims.holder is not None, **self.claims.status(),
            "lockstep_frozen": self._frozen,
            "rtt_p50_us": float(np.percentile(rtt, 50)) if n else None,
            "rtt_p99_us": float(np.percentile(rtt, 99)) if n else None,
            "rtt_samples": n, "process_cpu_s": time.process_time(), **fw,
        }

    def stop(self) -> None:
        """Ask :meth:`run` to return after the current tick (thread- and signal-safe)."""
        self._stop.set()
        if self._cond.acquire(blocking=False):  # never block inside a signal handler
            try:
                self._cond.notify_all()
            finally:
                self._cond.release()

    def run(self) -> None:
        """Serve until stopped; always closes the session and the log."""
        cfg = self.config
        try:
            self._open()
            if cfg.log:
                self._log = LogWriter(cfg.log, self.info, truth=True, extra=LOG_EXTRA,
                                      metadata={"servotau.source": "server", "servotau.clock": cfg.clock},
                                      realtime=not self.lockstep)
            with self._cond:
                self._frame = checked_frame(self.robot.read())
                self._serving = True
                self._publish()
            if self.lockstep:
                self._run_lockstep()
            else:
                self._run_realtime()
        finally:
            with self._cond:
                self._serving = False
            try:
                self.close()  # first: the controller sees the robot go away at once
            finally:
                if self._log is not None:
                    self._log.close()
        if self._error is not None:
            raise self._error

    def close(self) -> None:
        if self._session is not None:
            self._session.close()

    # -- internals ---------------------------------------------------------------------------------
    def _open(self) -> None:
        cfg, k = self.config, self.keys
        set_realtime_priority(cfg.realtime_priority)  # before the session: its threads inherit it
        s = self._session = Session(zenoh_config(listen=cfg.listen, connect=cfg.connect, mode=cfg.mode,
                                                 security=cfg.security, key_prefix=k.prefix))
        z = s.z
        cc = zenoh.CongestionControl.BLOCK if self.lockstep else zenoh.CongestionControl.DROP
        self._pub_frame = s.keep(z.declare_publisher(k.frame, express=True, congestion_control=cc,
                                                     priority=zenoh.Priority.REAL_TIME))
        self._pub_truth = s.keep(z.declare_publisher(k.truth, express=True, congestion_control=cc,
                                                     priority=zenoh.Priority.DATA_HIGH))
        self._truth_wanted = False  # somebody subscribes to the truth (no encoding for nobody)
        s.keep(self._pub_truth.declare_matching_listener(callback(self._on_truth_matching)))
        # direct: in lock-step the command ticks the robot in zenoh's network thread, no thread hand-over
        s.keep(z.declare_subscriber(k.command, callback(self._on_command, direct=True)))
        # the claimer's death, seen from its own session: its transport, or (router) its zid-scoped token
        s.keep(z.info.declare_transport_events_listener(callback(self._on_transport)))
        s.keep(z.liveliness().declare_subscriber(f"{k.alive_controller}/*", callback(self._on_controller_liveliness),
                                                 history=True))
        s.keep(z.declare_queryable(claim_key(k.prefix), callback(self._on_claim)))
        s.keep(z.declare_queryable(k.info, callback(self._on_query)))
        s.keep(z.declare_queryable(k.status, callback(self._on_query)))
        s.keep(z.declare_queryable(k.operator, callback(self._on_query)))
        s.keep(z.liveliness().declare_token(k.alive_robot))
        if self.on_ready is not None:
            self.on_ready()
        logger.info("serving %s on %s (%s, %s)", self.info.name, k.prefix, cfg.clock,
                    ", ".join(cfg.listen or cfg.connect))

    def _publish(self, truth: bool = True) -> None:
        """Publish the current frame, then its ground truth (under _cond): ``truth``, a new frame: read the truth
        (if somebody wants it or the log); else a republished frame: the truth read with it (read now if nobody
        wanted it then: the robot has not stepped since)."""
        frame = self._frame
        self._published = frame.seq
        self._t_published = time.monotonic()
        self.gate.published(frame.seq, frame.time)
        self._pub_frame.put(encode_frame(frame, self.firmware.flags))
        if truth:  # after the frame: off the controller's critical path; only if somebody wants it
            send = self.config.publish_truth and self._truth_wanted
            self._truth = self.robot.ground_truth() if send or self._log is not None else None
        self._put_truth()

    def _put_truth(self) -> None:
        """Publish the truth of the current frame if somebody wants it (under _cond)."""
        if not (self.config.publish_truth and self._truth_wanted) or self._frame is None:
            return
        if self._truth is None or self._truth.seq != self._frame.seq:
            self._truth = self.robot.ground_truth()
        if self._truth is not None:
            self._pub_truth.put(encode_truth(self._truth))

    def _tick(self, now: float) -> None:
        """Firmware, step, read, publish (under _cond). ``now``: wall time [s] (time.monotonic)."""
        fw, robot, frame, truth = self.firmware, self.robot, self._frame, self._truth
        if self._controller_lost:
            self._controller_lost = False
            fw.controller_lost()
        q_apply = fw.output(frame.q, now, int(frame.status[0]))
        state = float(fw.state)
        if q_apply is None:
            if not self._servo_off_sent:
                robot.servo_off()
                self._servo_off_sent = True
            robot.step(fw.last_valid(frame.q))  # finite even with NaN encoders; no current flows
        else:
            robot.step(q_apply)
        self.ticks += 1
        done = self.config.max_ticks is not None and self.ticks >= self.config.max_ticks
        if not done:
            self._frame = checked_frame(robot.read())
            self._publish()
        if self._log is not None:  # the row of tick k, once frame k+1 is on its way
            self._log.append(frame, q_apply, truth, {"hal/state": state, "hal/wall_time": now})
        if done:
            self._serving = False
            self._stop.set()
            self._cond.notify_all()

    def _run_lockstep(self) -> None:
        """Watchdog side of lock-step; commands tick the robot from the callback thread.

        A controller silent for ``hold_after`` of wall time while its liveliness token lives (hung, or slow)
        makes the robot hold *without stepping*: simulated time stands still, so nothing moves, and the frame is
        republished flagged HOLDING; the command answering it resumes exactly where the run was (a stall changes
        nothing in the log). Once the controller is lost, or for any other hold, the robot steps one tick per
        period of wall time, holding (so does a frozen robot once ``lockstep_servo_off_after`` is due: its next
        tick cuts the servos)."""
        period, safety, fw = self.info.period, self.firmware.safety, self.firmware
        with self._cond:
            while not self._stop.is_set():
                now = time.monotonic()
                state, commanded = fw.state, self._commanded()
                if self._frozen and (state != FirmwareState.HOLDING or self._controller_lost or fw.servo_off_due(now)):
                    self._frozen = False  # resumed by a command, the controller is gone, or servo_off_after: step on
                if not commanded:
                    self._controller_lost = False  # nothing to hold
                if commanded:
                    deadline = -math.inf if self._controller_lost else fw.last_command_time + safety.hold_after
                elif state == FirmwareState.WAITING or self._frozen:  # the robot does not move
                    deadline = self._t_published + self.config.republish_interval
                else:  # HOLDING or SERVO_OFF: nobody commands, step in real time
                    deadline = self._t_published + period
                if now < deadline:
                    self._cond.wait(deadline - now)
                elif state == FirmwareState.WAITING or self._frozen:
                    self._publish(truth=False)  # for controllers that join late; flagged HOLDING when frozen
                elif commanded and not self._controller_lost:
                    fw.watchdog(now)  # a hung controller: hold, frozen
                    self._frozen = True
                    self._publish(truth=False)
                else:
                    self._tick(now)  # the firmware holds (or stays off)

    def _commanded(self) -> bool:
        """The claimer drives the robot: RUNNING, or holding on its commands' COMMAND_HOLD (lock-step then waits for
        each command, as while running)."""
        return self.firmware.state == FirmwareState.RUNNING or self.firmware.hold_commanded

    def _run_realtime(self) -> None:
        period, paced = self.info.period, self.config.clock == "realtime"
        if paced:
            set_timer_slack(1000)
        next_t = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            if paced:
                next_t += period
                self._sleep_until(next_t)
                now = time.monotonic()
                if now - next_t > period:
                    self.late_ticks += 1
                    next_t = now  # late: do not burst to catch up
            with self._cond:
                if self._stop.is_set():
                    break
                if (taken := self._pending.take()) is not None:
                    q_des, t_recv, seq, hold, first = taken
                    self.firmware.accept(q_des, t_recv, hold, self.gate.newest - first)
                    self.gate.applied(seq)
                self._tick(now)

    def _sleep_until(self, deadline: float) -> None:
        """Sleep, never spin, until ``deadline`` (time.monotonic() [s]). With the timer slack at 1 us
        (:meth:`_run_realtime`) a sleep ends a few tens of us late; spinning the last 0.2 ms instead
        cost 20-30 % of a core and, on a loaded machine, ticks late by a period as often or more
        (20 s runs at load 5-6, late fraction spin / sleep: 0.0008 / 0.0003, 0.0019 / 0.0008,
        0.0020 / 0.0019)."""
        rem = deadline - time.monotonic()
        if rem > 0 and not self._stop.is_set():
            time.sleep(rem)


def serve(robot: ServedRobot, config: ServerConfig | None = None,
          on_ready: Callable[[], None] | None = None) -> RobotServer:
    """Serve ``robot`` in the calling thread until SIGINT/SIGTERM, ``max_ticks`` or an error."""
    server = RobotServer(robot, config, on_ready)
    handler = lambda *_: server.stop()  # noqa: E731
    old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)} \
        if threading.current_thread() is threading.main_thread() else {}
    try:
        server.run()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    return server
