"""``servotau control``: the controller process.

Connects to the robot through the HAL (backend chosen in config/hal.toml or by ``--backend``),
estimates joint torques, runs the right-leg swing in position or torque mode, records a Parquet log
and streams to Rerun. If the robot disappears it exits with code 4.

A safety trip does not end the process: it holds the last valid measured posture (latched; the torque
terms off, the integrals frozen), keeps answering every frame, prints the trip once (check, joint, value,
limit) and waits for the operator (``servotau ctl``, served on ``servotau/v1/<robot>/controller/operator``
over Zenoh): ``reset`` goes back to position control at the held posture (refused while the trip's cause
is still there), ``release`` ends the process cleanly, its log closed, with exit code 3. ``--hold-timeout
SECONDS`` releases by itself after that much robot time without an operator (scripts, CI, ``servotau
demo``); without it an interactive run holds until the operator acts. SIGTERM releases like ``release``.

The loop is :class:`servotau.control.loop.ControlLoop`; this module adds its hooks: the tracking error
(:class:`TrackingError`), the Parquet log (:class:`LogHook`) and the Rerun stream (:class:`RerunHook`).
"""

from __future__ import annotations

import dataclasses
import logging
import signal
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from servotau.apps.config_args import (
    CONTROL,
    ESTIMATION,
    HAL,
    add_config_args,
    config_files,
    controller_parts,
    hal_config,
)
from servotau.apps.viewer import RerunHook, RerunStream, open_recording
from servotau.control.loop import ControlLoop, LoopHook, Tick
from servotau.control.operator import OperatorChannel
from servotau.control.trajectory import right_leg_swing
from servotau.errors import ControlError, HalError

log = logging.getLogger(__name__)

TAIL = 0.5  # [s] after the swing, still run and evaluated
EXIT_JOIN_TIMEOUT = 2.0  # [s] wall time the exit waits for the closed backend's and log's threads to end
TRIP_JOINT, TRIP_JUMP = "RLEG_JOINT3", 0.2  # --trip-at: the reference jump [rad] that trips the command check


@dataclass(frozen=True)
class SessionResult:
    ticks: int
    sim_seconds: float
    wall_seconds: float
    max_error: dict  # joint -> max |q_des - q| [rad] during the motion
    tripped: str | None
    end: str = "completed"  # LoopResult.end: completed, released, hold_timeout
    resets: int = 0
    gaps: int = 0  # gaps of skipped frames
    missing_frames: int = 0
    longest_gap: int = 0  # [frames]
    gap_fallbacks: int = 0  # torque mode fell back to position control after a gap longer than max_gap


# -- hooks ----------------------------------------------------------------------------------------------
class TrackingError(LoopHook):
    """Max |q_ref - q| per joint [rad] on the encoders, after the settle phase."""

    def __init__(self, n: int):
        self.max = np.zeros(n)

    def on_tick(self, tick: Tick) -> None:
        if not tick.settling:
            np.maximum(self.max, np.abs(tick.reference.q - tick.frame.q), out=self.max)


class LogHook(LoopHook):
    """Every tick into a :class:`~servotau.hal.log.LogWriter`: frame, command, ground truth, estimated tau and dq."""

    wants_truth = True

    def __init__(self, writer):
        self.writer = writer

    def on_tick(self, tick: Tick) -> None:
        e = tick.estimate
        self.writer.append(tick.frame, tick.terms.q_des, tick.truth, {"est/tau": e.tau, "est/dq": e.dq})


class _Progress(LoopHook):
    def __init__(self, progress, mode: str, duration: float):
        self.progress, self.mode, self.duration = progress, mode, duration

    def settled(self, tick: Tick) -> None:
        self.progress(f"swinging the right leg in {self.mode} mode for {self.duration:.1f} s")


class _TripNotice(LoopHook):
    """Prints a trip once, with what the operator can do."""

    def __init__(self, progress, hint: str):
        self.progress, self.hint = progress, hint

    def tripped(self, tick: Tick, report) -> None:
        self.progress(f"SAFETY TRIP: {report.message}: holding the last valid measured posture; {self.hint}")


# -- the session ----------------------------------------------------------------------------------------
def register(sub) -> None:
    p = sub.add_parser("control", help="run the controller on a HAL backend (sim or real robot)")
    add_config_args(p, HAL, CONTROL, ESTIMATION)
    p.add_argument("--backend", choices=("zenoh", "inprocess", "replay"), help="override the config's backend")
    p.add_argument("--port", type=int, help="zenoh: the robot's port on 127.0.0.1 (overrides the config)")
    p.add_argument("--mode", choices=("position", "torque"), default="position")
    p.add_argument("--duration", type=float, default=3.0, help="swing duration [s]")
    p.add_argument("--log", default=None, help="Parquet log path")
    p.add_argument("--rerun", default="off", help="save:FILE | connect:ADDR | spawn[:PORT] | off")
    p.add_argument("--rerun-signals", choices=("minimal", "control", "all"), default="control",
                   help="what the Rerun recording holds (servotau/apps/viewer_layout.py; default: control)")
    p.add_argument("--rerun-robot-hz", type=float, default=20.0, help="[Hz] 3D robot poses per robot second (0: none)")
    p.add_argument("--hold-timeout", type=float, default=None, metavar="SECONDS",
                   help="[s] robot time a safety hold waits for the operator (servotau ctl reset|release) before "
                        "releasing by itself, exit code 3 (default: wait for the operator)")
    p.add_argument("--trip-at", type=float, default=None, metavar="SECONDS",
                   help="fault injection (tests, benchmarks): at this robot time after the settle phase the reference "
                        f"of {TRIP_JOINT} jumps by {TRIP_JUMP} rad, which trips the command_error check")
    p.set_defaults(func=main)


def run_session(backend, *, mode: str, duration: float, stream: RerunStream | None = None, writer=None,
                progress=print, operator: OperatorChannel | None = None, hold_timeout: float | None = 0.0,
                hint: str = "", trip_at: float | None = None, manager=None, estimator=None) -> SessionResult:
    """Settle, then swing the right leg in ``mode`` (:class:`~servotau.control.loop.ControlLoop`).

    Args:
        backend: The HAL backend.
        mode: ``position`` or ``torque``.
        duration: [s] of the swing (then :data:`TAIL` s holding its end).
        stream: Rerun stream, or None.
        writer: :class:`~servotau.hal.log.LogWriter`, or None.
        progress: Called with a line of text at the swing's start and on a safety trip.
        operator: Where the operator's reset/release/status arrive while holding after a trip, or None.
        hold_timeout: [s] robot time a trip's hold waits for a release (None: forever; 0: stop at the trip).
        hint: What the operator can do, printed with a trip.
        trip_at: [s] fault injection: the reference of :data:`TRIP_JOINT` jumps by :data:`TRIP_JUMP` from this
            robot time after the settle phase on (a command_error trip), or None.
        manager, estimator: The controller and the torque estimator (default: the packaged config).
    """
    info = backend.info
    error = TrackingError(info.nq)
    hooks = [error, _Progress(progress, mode, duration), _TripNotice(progress, hint or "stopping")]
    if writer is not None:
        hooks.append(LogHook(writer))
    if stream is not None:
        hooks.append(RerunHook(stream, info.ft_sensor_names))
    loop = ControlLoop(backend, manager, estimator, mode=mode, hooks=hooks)
    traj = right_leg_swing(info.joint_names, loop.start().q, duration)
    jump = np.zeros(info.nq)
    jump[info.joint_names.index(TRIP_JOINT)] = TRIP_JUMP

    def reference(tick: Tick):
        point = traj.sample(tick.t)
        if trip_at is not None and tick.t >= trip_at:
            point = dataclasses.replace(point, q=point.q + jump)
        return point

    result = loop.run(reference, duration + TAIL, operator=operator, hold_timeout=hold_timeout)
    return SessionResult(
        ticks=result.ticks, sim_seconds=result.sim_seconds, wall_seconds=result.wall_seconds,
        max_error={j: float(e) for j, e in zip(info.joint_names, error.max, strict=True)},
        tripped=result.tripped, end=result.end, resets=result.resets, gaps=result.gaps,
        missing_frames=result.missing_frames, longest_gap=result.longest_gap,
        gap_fallbacks=loop.manager.gap_fallbacks,
    )


def serve_operator(backend, operator: OperatorChannel) -> str | None:
    """Serve the operator query of ``backend``'s robot on the backend's own Zenoh session; returns its key, or
    None for a backend without one (in-process, replay: only ``--hold-timeout`` or Ctrl-C end a hold)."""
    declare = getattr(backend, "declare_queryable", None)
    if declare is None:
        return None
    key = f"{backend.keys.prefix}/controller/operator"

    def on_query(query) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else None
        query.reply(key, operator.handle(payload).to_json())

    declare(key, on_query)
    return key


def quiesce_threads(before: set[int] = frozenset(), timeout: float = EXIT_JOIN_TIMEOUT) -> list[str]:
    """Wait (at most ``timeout`` [s] of wall time in all) for the Python threads started since ``before`` (thread
    idents) to end; return the names of those still running.

    Why: once the interpreter starts finalizing, CPython ends any thread that takes the GIL with
    ``pthread_exit``; in a thread that is inside native code at that moment (zenoh's pyo3 bindings, e.g. the
    backend's read-alarm thread in a ``put``, or a callback thread handing over a sample; pyarrow in a log
    writer) the forced unwind crosses a Rust ``catch_unwind`` that swallows it, and glibc aborts the process
    with "FATAL: exception not rethrown" (SIGABRT instead of the exit code). After the log, the stream and the
    backend are closed, their threads end within a few milliseconds: joining them first leaves the interpreter
    nothing to kill.
    """
    deadline = time.monotonic() + timeout
    me = threading.current_thread()
    ours = [t for t in threading.enumerate() if t is not me and t.ident not in before]
    for t in ours:
        t.join(max(deadline - time.monotonic(), 0.0))
    left = [t.name for t in ours if t.is_alive()]
    if left:
        log.warning("threads still running at exit: %s", ", ".join(left))
    return left


def _on_wall_clock(backend) -> bool:
    """The robot paces the loop on the wall clock (its status says so): the log must never make the loop wait
    (a lock-step robot waits for the controller, so its log keeps every row)."""
    try:
        return backend.status().get("clock", "lockstep") != "lockstep"
    except HalError:
        return False


def main(args) -> int:
    from servotau.hal.log import LogWriter
    from servotau.hal.registry import open_backend, overrides_from_args

    if args.hold_timeout is not None and not args.hold_timeout >= 0:
        raise ControlError(f"--hold-timeout {args.hold_timeout}: expected >= 0 [s]")
    threads_before = {t.ident for t in threading.enumerate()}
    files = config_files(args, HAL, CONTROL, ESTIMATION)
    backend = open_backend(hal_config(files), **overrides_from_args(args))
    operator = OperatorChannel()
    writer = stream = None
    old_term = signal.signal(signal.SIGTERM, lambda *_: operator.post("release")) \
        if threading.current_thread() is threading.main_thread() else None
    try:
        key = serve_operator(backend, operator)
        robot = getattr(backend, "robot_name", backend.info.name)
        hint = (f"servotau ctl reset|release --robot {robot} (query {key})" if key else "Ctrl-C to stop")
        if args.hold_timeout is not None:
            hint += f"; releasing by itself after {args.hold_timeout:g} s"
        rec = open_recording(args.rerun)
        stream = RerunStream(rec, backend.info.joint_names, backend.info.model_path, signals=args.rerun_signals,
                             ft_sensor_names=backend.info.ft_sensor_names,
                             robot_hz=args.rerun_robot_hz) if rec is not None else None
        writer = LogWriter(args.log, backend.info, metadata={"mode": args.mode},
                           realtime=_on_wall_clock(backend)) if args.log else None
        result = run_session(backend, mode=args.mode, duration=args.duration, stream=stream, writer=writer,
                             operator=operator, hold_timeout=args.hold_timeout, hint=hint, trip_at=args.trip_at,
                             **controller_parts(files, backend.info))
    except HalError as exc:
        print(f"servotau control: robot lost: {exc}", file=sys.stderr)
        return 4
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        try:
            if writer is not None:
                writer.close()
            if stream is not None:
                st = stream.close()
                print(f"rerun: {st.rows} ticks, {st.robot_seconds:.2f} s robot time, recording CPU {st.cpu_s:.2f} s "
                      f"(control thread {st.caller_cpu_s:.2f} s, sender thread {st.sender_cpu_s:.2f} s)")
        finally:
            backend.close()
            quiesce_threads(threads_before)
    legs = [j for j in backend.info.joint_names if j.startswith("RLEG")]
    print(f"{result.ticks} ticks, {result.sim_seconds:.2f} s robot time in {result.wall_seconds:.2f} s wall "
          f"({result.sim_seconds / result.wall_seconds:.2f}x real time); {result.missing_frames} frames skipped in "
          f"{result.gaps} gaps (longest {result.longest_gap}; {result.gap_fallbacks} fallbacks to position control)")
    print("max |q_ref - q| [mrad]: " + ", ".join(f"{j} {1e3 * result.max_error[j]:.1f}" for j in legs))
    if result.tripped:
        how = {"released": "released: servotau ctl release or SIGTERM", "hold_timeout": "released after --hold-timeout"}
        print(f"safety trip: {result.tripped} ({how.get(result.end, result.end)}; {result.resets} resets)",
              file=sys.stderr)
        return 3
    if result.end != "completed":
        print("servotau control: released before the end of the swing", file=sys.stderr)
        return 130
    return 0
