"""Stream robot signals and the 3D robot to Rerun.

Targets (``--rerun``): ``save:FILE`` (a .rrd file), ``connect:ADDR`` (a viewer the user started, e.g. ``rerun
--bind 127.0.0.1`` then ``connect:rerun+http://127.0.0.1:9876/proxy``; default address that one), ``spawn`` or
``spawn:PORT`` (start a viewer listening on 127.0.0.1 only, port 9876 by default, and connect to it), ``memory``
(tests), ``off``.

What is recorded, under which entity and with which unit: servotau/apps/viewer_layout.py (signal sets
``minimal``, ``control``, ``all``); the robot: servotau/apps/viewer_robot.py. Scalars are buffered and sent in
columns, one entity per signal with one instance per joint, from a background thread: the control loop waits for
Rerun only when 8 batches are queued (Rerun slower than the loop), and a batch Rerun refuses is dropped and counted.
The 3D robot is one Transform3D per body per logged tick at ``robot_hz``.
"""

from __future__ import annotations

import logging
import queue
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rerun as rr

from servotau.apps.viewer_layout import ENTITY, MODES, Channel, blueprint, channels, joint_groups
from servotau.apps.viewer_robot import RobotTree
from servotau.control.loop import LoopHook, Tick
from servotau.errors import ConfigError
from servotau.hal.types import FT_SENSOR_NAMES

TIMELINE = "sim_time"
LOCAL_PORT = 9876  # the rerun viewer's default gRPC port
VIEWER_START_S = 10.0  # [s] wall time a spawned viewer gets to listen


def _spawn_local(port: int) -> str:
    """Start the rerun viewer listening on 127.0.0.1:``port``; its gRPC address."""
    import socket

    exe = shutil.which("rerun", path=str(Path(sys.executable).parent)) or "rerun"  # the one of this environment
    subprocess.Popen([exe, "--bind", "127.0.0.1", "--port", str(port)], stdin=subprocess.DEVNULL,
                     start_new_session=True)
    deadline = time.monotonic() + VIEWER_START_S
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return f"rerun+http://127.0.0.1:{port}/proxy"
        time.sleep(0.1)
    raise ConfigError(f"--rerun spawn:{port}: the viewer ({exe}) did not listen on 127.0.0.1:{port} within "
                      f"{VIEWER_START_S:g} s: expected a rerun viewer (pip package rerun-sdk) on this machine")


def open_recording(target: str, app_id: str = "servotau") -> rr.RecordingStream | None:
    """A recording stream for ``target`` (see module doc); None for ``off``."""
    kind, _, arg = target.partition(":")
    if kind == "off":
        return None
    rec = rr.RecordingStream(app_id)
    if kind == "save" and arg:
        rec.save(arg)
    elif kind == "connect":
        rec.connect_grpc(arg or f"rerun+http://127.0.0.1:{LOCAL_PORT}/proxy")
    elif kind == "spawn":
        if arg and not arg.isdigit():
            raise ConfigError(f"--rerun {target!r}: expected spawn or spawn:PORT (a port number)")
        rec.connect_grpc(_spawn_local(int(arg or LOCAL_PORT)))
    elif kind == "memory":
        rec.memory_recording()
    else:
        raise ConfigError(f"--rerun {target!r}: expected save:FILE, connect:ADDR, spawn[:PORT], memory or off")
    return rec


@dataclass(frozen=True)
class StreamStats:
    """What a closed stream cost: rows sent, robot time covered [s], CPU time [s] in the caller and the sender."""

    rows: int
    robot_seconds: float
    caller_cpu_s: float
    sender_cpu_s: float

    @property
    def cpu_s(self) -> float:
        return self.caller_cpu_s + self.sender_cpu_s


class RerunStream:
    """Buffered streaming of the signals of one signal set, safety events and the 3D robot to one recording."""

    def __init__(
        self,
        rec: rr.RecordingStream | None,
        joint_names: Sequence[str],
        model_path: str,
        *,
        signals: str = "control",
        ft_sensor_names: Sequence[str] = FT_SENSOR_NAMES,
        plot_joints: Sequence[str] | None = None,
        flush_every: int = 500,
        robot_hz: float = 20.0,
        robot_batch: int = 100,
    ):
        """``signals``: the signal set (viewer_layout.py); ``robot_hz``: transforms per robot second [Hz] (0: no
        3D robot); ``plot_joints``: the joints with a plot (default: the first six); ``flush_every``: ticks per
        batch sent (a viewer sees the data that late; each batch costs about 1.5 kB per entity of Arrow schema);
        ``robot_batch``: robot poses per batch (one batch holds a chunk per body)."""
        if not robot_hz >= 0:
            raise ConfigError(f"rerun robot rate {robot_hz}: expected >= 0 [Hz]")
        self.rec = rec
        self.joint_names = tuple(joint_names)
        self.channels: dict[str, Channel] = channels(signals, ft_sensor_names)
        self.flush_every = int(flush_every)
        self.robot_batch = int(robot_batch)
        self._robot_dt = 1.0 / robot_hz if robot_hz > 0 else np.inf
        self._times = np.empty(self.flush_every)  # [s] of the buffered ticks
        self._buf: dict[str, np.ndarray] = {}  # signal -> (flush_every, width) float32, NaN where not given
        self._robot: tuple[list[float], list[np.ndarray], list[np.ndarray]] = ([], [], [])
        self._last_robot_t = -np.inf
        self._ticks = self.rows = 0
        self._t0 = self._t1 = np.nan
        self._caller_cpu = self._sender_cpu = 0.0
        self.dropped = 0  # batches Rerun refused (dropped by the sender thread)
        self._mode: str | None = None
        if rec is None:
            return
        self.tree = RobotTree(model_path, self.joint_names) if robot_hz > 0 else None
        pj = list(plot_joints or self.joint_names[:6])
        bad = [j for j in pj if j not in self.joint_names]
        if bad:
            raise ConfigError(f"rerun plot joints {bad}: expected names among {list(self.joint_names)}")
        self._groups: dict[str, list[Channel]] = joint_groups(self.channels)
        rec.send_blueprint(blueprint(self.channels, pj))
        rec.log("safety/mode", rr.SeriesLines(names=["mode (0 position, 1 torque, 2 hold)"],
                                              interpolation_mode="StepAfter"), static=True)
        if self.tree is not None:
            self.tree.log_static(rec)
        self._queue: queue.Queue = queue.Queue(maxsize=8)
        self._worker = threading.Thread(target=self._send_loop, name="rerun-flush", daemon=True)
        self._worker.start()

    def add(self, time: float, **signals: np.ndarray) -> None:
        """Buffer one tick of signals at robot time ``time`` [s]; names outside the signal set are skipped."""
        if self.rec is None:
            return
        c0 = _cpu()
        k = self._ticks
        self._times[k] = time
        for name, value in signals.items():
            if value is None or name not in self.channels:
                continue
            buf = self._buf.get(name)
            if buf is None:
                buf = self._buf[name] = np.full((self.flush_every, np.size(value)), np.nan, dtype=np.float32)
            buf[k] = np.ravel(value)
        self._tick_done(time, c0)

    def event(self, time: float, text: str, level: str = "INFO") -> None:
        """A safety event (mode change, trip) at robot time ``time`` [s]."""
        if self.rec is None:
            return
        self._queue_item(("event", time, text, level))

    def mode(self, time: float, mode: str) -> None:
        """The controller's mode (position, torque, hold) at ``time`` [s]: logged when it changes."""
        if self.rec is None or mode == self._mode:
            return
        self._queue_item(("mode", time, float(MODES.index(mode)) if mode in MODES else np.nan, mode))
        if self._mode is not None:
            self.event(time, f"mode: {self._mode} -> {mode}", "WARN" if mode == "hold" else "INFO")
        self._mode = mode

    def robot(self, time: float, q: np.ndarray, base_position=None, base_quat_wxyz=None) -> None:
        """Buffer the robot's body transforms at joint angles ``q`` [rad] (rate-limited to ``robot_hz``)."""
        if self.rec is None or self.tree is None or time - self._last_robot_t < self._robot_dt:
            return
        c0 = _cpu()
        self._last_robot_t = time
        t, quat = self.tree.transforms(q, base_position, base_quat_wxyz)
        self._robot[0].append(time)
        self._robot[1].append(t)
        self._robot[2].append(quat)
        if len(self._robot[0]) >= self.robot_batch:
            self._flush_robot()
        self._caller_cpu += _cpu() - c0

    def _tick_done(self, time: float, c0: float) -> None:
        self._t0 = time if np.isnan(self._t0) else self._t0
        self._t1 = time
        self._ticks += 1
        self.rows += 1
        self._caller_cpu += _cpu() - c0
        if self._ticks >= self.flush_every:
            self.flush()

    def _queue_item(self, item) -> None:
        self.flush()
        self._queue.put(item)

    def flush(self) -> None:
        """Hand the buffered scalars and transforms to the sending thread."""
        if self.rec is None:
            return
        c0 = _cpu()
        k = self._ticks
        if k and self._buf:
            self._queue.put(("scalars", self._times[:k].copy(), {n: b[:k] for n, b in self._buf.items()}))
            self._buf = {}
        self._ticks = 0
        self._caller_cpu += _cpu() - c0

    def _flush_robot(self) -> None:
        if self._robot[0]:
            self._queue.put(("robot", *(np.asarray(x) for x in self._robot)))
            self._robot = ([], [], [])

    def _send_loop(self) -> None:
        """Send the queued batches until None; a batch Rerun refuses is dropped and counted (the first one
        logged): the queue keeps draining, so the control loop never waits on a dead sender."""
        while (item := self._queue.get()) is not None:
            c0 = time.thread_time()
            try:
                self._send(item)
            except Exception as exc:  # anything Rerun raises: the recording must not stop the loop
                self.dropped += 1
                if self.dropped == 1:
                    logging.getLogger(__name__).error("rerun: a %s batch could not be sent (%s); dropping it and "
                                                      "counting further ones", item[0], exc)
            self._sender_cpu += time.thread_time() - c0

    def _send(self, item) -> None:
        kind, rec = item[0], self.rec
        if kind == "scalars":
            self._send_scalars(item[1], item[2])
        elif kind == "robot":
            times, trans, quats = item[1:]
            index = [rr.TimeColumn(TIMELINE, duration=times)]
            for i, path in enumerate(self.tree.paths):
                rec.send_columns(path, index, rr.Transform3D.columns(translation=trans[:, i].astype(np.float32),
                                                                     quaternion=quats[:, i].astype(np.float32)))
        elif kind == "mode":
            rec.set_time(TIMELINE, duration=item[1])
            rec.log("safety/mode", rr.Scalars(item[2]))
        elif kind == "event":
            rec.set_time(TIMELINE, duration=item[1])
            rec.log("safety/events", rr.TextLog(item[2], level=item[3]))

    def _send_scalars(self, times: np.ndarray, bufs: dict[str, np.ndarray]) -> None:
        """One send of every signal to :data:`ENTITY` (NaN on the ticks a signal missed): a component per joint
        for each joint group, its instances the group's signals; a component per sensor quantity."""
        n, nj = len(times), len(self.joint_names)
        cols = []
        for group, chs in self._groups.items():
            stack = np.full((n, nj, len(chs)), np.nan, dtype=np.float32)
            for i, ch in enumerate(chs):
                if ch.field in bufs:
                    stack[:, :, i] = bufs[ch.field]
            cols += [_column(group, j, stack[:, k, :]) for k, j in enumerate(self.joint_names)]
        for name, ch in self.channels.items():
            if not ch.per_joint:
                values = bufs.get(name)
                cols.append(_column(ch.entity, ch.field, values if values is not None else
                                    np.full((n, len(ch.names)), np.nan, dtype=np.float32)))
        self.rec.send_columns(ENTITY, [rr.TimeColumn(TIMELINE, duration=times)], cols)

    def close(self) -> StreamStats:
        """Send what is buffered, wait for the sending thread, flush and close the recording (a file gets its
        footer); what the stream cost."""
        if self.rec is not None:
            self.flush()
            self._flush_robot()
            self._queue.put(None)
            self._worker.join()
            c0 = _cpu()
            self.rec.flush()
            self.rec.disconnect()
            self._caller_cpu += _cpu() - c0
        span = 0.0 if np.isnan(self._t0) else float(self._t1 - self._t0)
        return StreamStats(self.rows, span, self._caller_cpu, self._sender_cpu)


def _column(archetype: str, field: str, values: np.ndarray) -> rr.ComponentColumn:
    """Component ``<archetype>:<field>``: a row per tick, ``values`` (ticks, instances) as float32."""
    import pyarrow as pa

    n, k = values.shape
    lists = pa.ListArray.from_arrays(pa.array(np.arange(0, n * k + 1, k, dtype=np.int32)),
                                     pa.array(np.ascontiguousarray(values, dtype=np.float32).ravel()))
    return rr.AnyBatchValue.column(rr.ComponentDescriptor(component=field).with_builtin_archetype(archetype), lists)


def _cpu() -> float:
    return time.thread_time()


class RerunHook(LoopHook):
    """Every tick of the control loop to a :class:`RerunStream`: the signals of its signal set, the mode and
    safety trips, the 3D robot (at the ground-truth base pose when the backend has one)."""

    wants_truth = True

    def __init__(self, stream: RerunStream, ft_sensor_names: Sequence[str] = FT_SENSOR_NAMES):
        self.stream = stream
        self.ft_sensor_names = tuple(ft_sensor_names)
        self.want = set(stream.channels)

    def on_tick(self, tick: Tick) -> None:
        frame, terms, truth, est = tick.frame, tick.terms, tick.truth, tick.estimate
        want = self.want
        signals = {"q": frame.q, "q_des": terms.q_des, "tau_est": est.tau}
        if tick.reference is not None:
            signals["q_ref"] = tick.reference.q
        if "ff_torque" in want:
            signals.update(terms.components())
            signals["tau_d"] = terms.tau_d
            signals["imu/gyro"] = frame.imu_angular_velocity
            signals["imu/acc"] = frame.imu_linear_acceleration
            for s, name in enumerate(self.ft_sensor_names):
                signals[f"ft/{name}/force"] = frame.wrenches[s, :3]
                signals[f"ft/{name}/torque"] = frame.wrenches[s, 3:]
            if truth is not None:
                signals["tau_true"] = truth.tau
        if "e_q" in want:
            signals.update(tau_star=terms.tau_star, e_tau=terms.e_tau, e_q=terms.e_q, de_q=terms.de_q,
                           dde_q=terms.dde_q, dq_est=est.dq)
            signals.update({f"task/{n}": getattr(terms, n) for n in ("f_d", "f_hat", "e_f")})
        self.stream.mode(frame.time, str(terms.mode))
        self.stream.add(frame.time, **signals)
        base = (truth.base_position, truth.base_quat_wxyz) if truth is not None else (None, None)
        self.stream.robot(frame.time, frame.q, *base)

    def tripped(self, tick: Tick, report) -> None:
        self.stream.event(tick.frame.time, f"SAFETY TRIP: {report.message}", "ERROR")
