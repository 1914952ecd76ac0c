"""``servotau control``: the controller process.

Connects to the robot through the HAL (backend chosen in config/hal.toml or by ``--backend``), estimates joint
torques and runs a task (``--task``: a name of config/tasks/, a task file, or ``module:attribute`` of a Python
task; default ``swing``, the paper's right-leg swing) until the task ends or it is stopped, records a Parquet
log (with the backend's ground truth, ``true/*``, when it has one) and streams to Rerun. The task is checked
against the robot's limits on the first frame: an infeasible one is refused (exit code 2) before any command.
About once a second of robot time a status line says the robot time, the mode, the phase, the worst tracking
and torque errors and the safety state. If the robot disappears it exits with code 4.

Stopping: Ctrl-C, SIGTERM or ``servotau ctl stop`` bring the reference to rest and the controller to position
mode (bumpless), then the process exits 0 with its log closed; a second Ctrl-C or SIGTERM releases at once.
``servotau ctl position|torque`` switches the mode, ``servotau ctl start TASK`` replaces the running task.

A safety trip does not end the process: it holds the last valid measured posture (latched; the torque
terms off, the integrals frozen), keeps answering every frame, prints the trip once (check, joint, value,
limit) and waits for the operator (``servotau ctl``, served on ``servotau/v1/<robot>/controller/operator``
over Zenoh): ``reset`` goes back to position control at the held posture (refused while the trip's cause
is still there), ``release`` or ``stop`` end the process cleanly, its log closed, with exit code 3.
``--hold-timeout SECONDS`` releases by itself after that much robot time without an operator (scripts, CI,
``servotau demo``); without it an interactive run holds until the operator acts.

The loop is :class:`servotau.control.loop.ControlLoop` driven by a :class:`servotau.control.tasks.TaskRunner`;
this module adds its hooks: the tracking error (:class:`TrackingError`), the Parquet log (:class:`LogHook`) and
the Rerun stream (:class:`RerunHook`).
"""

from __future__ import annotations

import dataclasses
import logging
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from servotau.apps.config_args import (
    CONTROL,
    ESTIMATION,
    HAL,
    add_config_args,
    config_files,
    hal_config,
    torque_estimator,
)
from servotau.apps.viewer import RerunHook, RerunStream, open_recording
from servotau.control.config import DEFAULT_PATH as DEFAULT_CONTROL
from servotau.control.loop import ControlLoop, LoopHook, Tick
from servotau.control.operator import OperatorChannel
from servotau.control.tasks import InfeasibleTask, StatusLine, Task, TaskRunner, resolve_task
from servotau.control.tasks.spec import is_task_name
from servotau.errors import ConfigError, ControlError, HalError

log = logging.getLogger(__name__)

DEFAULT_TASK = "swing"  # config/tasks/swing.toml: the paper's right-leg swing, then 0.5 s holding its end
EXIT_JOIN_TIMEOUT = 2.0  # [s] wall time the exit waits for the closed backend's and log's threads to end
TRIP_JOINT, TRIP_JUMP = "RLEG_JOINT3", 0.2  # --trip-at: the reference jump [rad] that trips the command check


@dataclass(frozen=True)
class SessionResult:
    ticks: int
    sim_seconds: float
    wall_seconds: float
    max_error: dict  # joint -> max |q_ref - q| [rad] after the settle phase
    tripped: str | None
    end: str = "completed"  # LoopResult.end: completed, stopped, released, hold_timeout
    resets: int = 0
    gaps: int = 0  # gaps of skipped frames
    missing_frames: int = 0
    longest_gap: int = 0  # [frames]
    gap_fallbacks: int = 0  # torque mode fell back to position control after a gap longer than max_gap
    phase: str = ""  # the phase running at the end


# -- hooks ----------------------------------------------------------------------------------------------
class TrackingError(LoopHook):
    """Max |q_ref - q| per joint [rad] on the encoders, after the settle phase."""

    def __init__(self, n: int):
        self.max = np.zeros(n)

    def on_tick(self, tick: Tick) -> None:
        if not tick.settling:
            np.maximum(self.max, np.abs(tick.reference.q - tick.frame.q), out=self.max)


class LogHook(LoopHook):
    """Every tick into a :class:`~servotau.hal.log.LogWriter`: frame, command, ground truth, estimated tau and dq.

    Whether the log has ground-truth columns (``true/*``) is decided by the first :data:`TRUTH_PROBE` ticks: a
    backend's truth may miss the first frames (over Zenoh the robot publishes frame 0's before the controller
    listens), so the rows wait until one has truth, or until the probe ends (then no truth columns). Call
    :meth:`flush` at the end of a run shorter than the probe.
    """

    wants_truth = True
    TRUTH_PROBE = 50  # [ticks]

    def __init__(self, writer):
        self.writer = writer
        self._rows: list | None = None if writer.truth_decided else []

    def on_tick(self, tick: Tick) -> None:
        e = tick.estimate
        if self._rows is None:
            self.writer.append(tick.frame, tick.terms.q_des, tick.truth, {"est/tau": e.tau, "est/dq": e.dq})
            return
        self._rows.append((tick.frame, tick.terms.q_des.copy(), tick.truth,
                           {"est/tau": e.tau.copy(), "est/dq": e.dq.copy()}))
        if tick.truth is not None or len(self._rows) >= self.TRUTH_PROBE:
            self.flush()

    def flush(self) -> None:
        """Decide the truth columns (a row with truth so far) and write the rows held back."""
        if self._rows is None:
            return
        rows, self._rows = self._rows, None
        self.writer.set_truth(any(r[2] is not None for r in rows))
        for row in rows:
            self.writer.append(*row)


class SaveOffsets(LoopHook):
    """Writes the F/T offsets in use after the settle phase to a TOML file ``sensor = [fx, fy, fz, tx, ty, tz]``
    [N, N m] (what :func:`load_ft_offsets` reads)."""

    def __init__(self, path: str, estimator, sensor_names):
        self.path, self.estimator, self.sensor_names = path, estimator, tuple(sensor_names)

    def settled(self, tick: Tick) -> None:
        from servotau.actuator.toml_writer import dumps

        offsets = {name: [float(v) for v in row]
                   for name, row in zip(self.sensor_names, self.estimator.ft_offsets, strict=True)}
        header = [f"F/T offsets [N, N m] calibrated in the settle phase of servotau control (robot time "
                  f"{tick.frame.time:.3f} s); servotau control --ft-offsets reads them"]
        with open(self.path, "w", encoding="utf-8") as f:
            f.write(dumps(offsets, header))


class _ModeOverride(Task):
    """A task with every phase in ``mode`` (``--mode``)."""

    def __init__(self, task: Task, mode: str):
        self.task, self.mode = task, mode
        self.name, self.source = task.name, task.source
        self.settle, self.ft_offsets = getattr(task, "settle", 0.5), getattr(task, "ft_offsets", "calibrate")

    def phases(self, info, q_start):
        out = []
        for p in self.task.phases(info, q_start):
            if p.force is not None and self.mode != "torque":
                raise ConfigError(f'{self.source}: phase "{p.name}" has a force task: --mode {self.mode} '
                                  "expected torque (or no --mode)")
            out.append(dataclasses.replace(p, mode=self.mode, gains=p.gains if self.mode == "torque" else {}))
        return out


class _TripNotice(LoopHook):
    """Prints a trip once, with what the operator can do."""

    def __init__(self, progress, hint: str):
        self.progress, self.hint = progress, hint

    def tripped(self, tick: Tick, report) -> None:
        self.progress(f"SAFETY TRIP: {report.message}: holding the last valid measured posture; {self.hint}")


# -- the session ----------------------------------------------------------------------------------------
def register(sub) -> None:
    p = sub.add_parser("control", help="run the controller on a HAL backend (sim or real robot): a task until it "
                                       "ends or is stopped")
    add_config_args(p, HAL, CONTROL, ESTIMATION)
    p.add_argument("--backend", choices=("zenoh", "inprocess", "replay"), help="override the config's backend")
    p.add_argument("--port", type=int, help="zenoh: the robot's port on 127.0.0.1 (overrides the config)")
    p.add_argument("--task", default=DEFAULT_TASK, metavar="TASK",
                   help="a name of config/tasks/ (hold, swing, force, identification, table_example), a task file, "
                        f"or module:attribute of a Python task (default: {DEFAULT_TASK})")
    p.add_argument("--mode", choices=("position", "torque"), default=None,
                   help="the mode of every phase (default: each phase's own)")
    p.add_argument("--duration", type=float, default=None, metavar="SECONDS",
                   help="[s] the length of the task's duration_phase (swing: the swing, default 3 s; a duration too "
                        "short for the safety's limits, the speed the estimator will read with a margin, the torque "
                        "or the command error, is refused before anything moves with the duration it needs: "
                        "position mode at least 1.65 s, torque mode 1.76 s)")
    p.add_argument("--ft-offsets", default=None, metavar="FILE",
                   help='TOML of F/T offsets [N, N m], sensor = [fx, fy, fz, tx, ty, tz], for tasks with '
                        'settle.ft_offsets = "external" (measured with the feet free)')
    p.add_argument("--save-ft-offsets", default=None, metavar="FILE",
                   help="write the F/T offsets calibrated in the settle phase to FILE (TOML, for --ft-offsets: "
                        "calibrate with the feet free, e.g. hanging, then run a task on the loaded feet)")
    p.add_argument("--log", default=None, help="Parquet log path")
    p.add_argument("--rerun", default="off", help="save:FILE | connect:ADDR | spawn[:PORT] | off")
    p.add_argument("--rerun-signals", choices=("minimal", "control", "all"), default="control",
                   help="what the Rerun recording holds (servotau/apps/viewer_layout.py; default: control)")
    p.add_argument("--rerun-robot-hz", type=float, default=20.0, help="[Hz] 3D robot poses per robot second (0: none)")
    p.add_argument("--quiet", action="store_true", help="no status line once a second")
    p.add_argument("--hold-timeout", type=float, default=None, metavar="SECONDS",
                   help="[s] robot time a safety hold waits for the operator (servotau ctl reset|release) before "
                        "releasing by itself, exit code 3 (default: wait for the operator)")
    p.add_argument("--trip-at", type=float, default=None, metavar="SECONDS",
                   help="fault injection (tests, benchmarks): at this robot time after the settle phase the reference "
                        f"of {TRIP_JOINT} jumps by {TRIP_JUMP} rad, which trips the command_error check")
    p.set_defaults(func=main)


def load_ft_offsets(path: str, info) -> Callable:
    """``ft_offsets`` for the loop from a TOML file ``sensor = [6 numbers]`` (every F/T sensor of ``info``)."""
    from servotau.config import load_toml

    root = load_toml(path)
    root.check_keys(info.ft_sensor_names)
    offsets = np.array([root.floats(s, 6, unit="N, N m") for s in info.ft_sensor_names])
    return lambda frames: offsets


def run_session(backend, *, task: Task | str = DEFAULT_TASK, mode: str | None = None, duration: float | None = None,
                stream: RerunStream | None = None, writer=None, progress=print, operator: OperatorChannel | None = None,
                hold_timeout: float | None = 0.0, hint: str = "", trip_at: float | None = None,
                ft_offsets: Callable | None = None, status: bool = False, save_ft_offsets: str | None = None,
                loop_ready: Callable[[ControlLoop], None] | None = None, control_path=None,
                estimator=None) -> SessionResult:
    """Settle, then run ``task`` (:class:`~servotau.control.tasks.TaskRunner` on a
    :class:`~servotau.control.loop.ControlLoop`) until it ends, is stopped or released.

    Args:
        backend: The HAL backend.
        task: A task, or a name of config/tasks/, a task file, ``module:attribute``.
        mode: ``position`` or ``torque`` for every phase (None: each phase's own).
        duration: [s] of the task's ``duration_phase`` (None: the file's).
        stream: Rerun stream, or None.
        writer: :class:`~servotau.hal.log.LogWriter`, or None.
        progress: Called with a line of text at each phase's start, on a safety trip and for the status line.
        operator: Where the operator's actions arrive (``servotau ctl``), or None.
        hold_timeout: [s] robot time a trip's hold waits for a release (None: forever; 0: stop at the trip).
        hint: What the operator can do, printed with a trip.
        trip_at: [s] fault injection: the reference of :data:`TRIP_JOINT` jumps by :data:`TRIP_JUMP` from this
            robot time after the settle phase on (a command_error trip), or None.
        ft_offsets: The loop's F/T offsets (``f(settle_frames)``) for tasks with external offsets.
        status: Print the status line once a second of robot time.
        save_ft_offsets: Write the F/T offsets in use after the settle phase to this TOML file.
        loop_ready: Called with the loop once built (e.g. to stop it from a signal handler).
        control_path, estimator: The controller's config file (default: the packaged control.toml; the task's gains
            apply on top) and the torque estimator (default: the packaged estimation.toml).

    Raises:
        InfeasibleTask: The task leaves the robot's limits (nothing was sent).
        ConfigError: The task cannot be read, imported or built.
    """
    info = backend.info
    if isinstance(task, str):
        task = resolve_task(task, duration)
    elif duration is not None:
        raise ConfigError("duration: applies to a task given by name or file")
    if mode is not None:
        task = _ModeOverride(task, mode)
    shape = None
    if trip_at is not None:
        if TRIP_JOINT not in info.joint_names:
            raise ConfigError(f"--trip-at: the fault injection moves {TRIP_JOINT}, which {info.name} does not have")
        jump = np.zeros(info.nq)
        jump[info.joint_names.index(TRIP_JOINT)] = TRIP_JUMP

        def shape(tick: Tick, point):  # the task's reference only: the loop's holds and stops stay as they are
            return dataclasses.replace(point, q=point.q + jump) if tick.t >= trip_at else point

    runner = TaskRunner(task, info, progress=progress, control=control_path or DEFAULT_CONTROL, shape=shape)
    error = TrackingError(info.nq)
    hooks = [runner, error, _TripNotice(progress, hint or "stopping")]
    log_hook = LogHook(writer) if writer is not None else None
    if log_hook is not None:
        hooks.append(log_hook)
    if stream is not None:
        hooks.append(RerunHook(stream, info.ft_sensor_names))
    loop = ControlLoop(backend, runner.manager(), estimator, hooks=hooks, settle=task.settle,
                       ft_offsets=runner.ft_offsets(ft_offsets))
    if status:
        loop.hooks = (*loop.hooks, StatusLine(loop, progress, runner))
    if save_ft_offsets:
        try:
            open(save_ft_offsets, "a", encoding="utf-8").close()  # a bad path fails here, before the first command
        except OSError as exc:
            raise ConfigError(f"--save-ft-offsets {save_ft_offsets}: cannot write it ({exc.strerror})") from None
        loop.hooks = (*loop.hooks, SaveOffsets(save_ft_offsets, loop.estimator, info.ft_sensor_names))
    if loop_ready is not None:
        loop_ready(loop)
    try:
        result = runner.run(loop, operator=operator, hold_timeout=hold_timeout)  # InfeasibleTask: nothing sent
    finally:
        if log_hook is not None:
            log_hook.flush()
    return SessionResult(
        ticks=result.ticks, sim_seconds=result.sim_seconds, wall_seconds=result.wall_seconds,
        max_error={j: float(e) for j, e in zip(info.joint_names, error.max, strict=True)},
        tripped=result.tripped, end=result.end, resets=result.resets, gaps=result.gaps,
        missing_frames=result.missing_frames, longest_gap=result.longest_gap,
        gap_fallbacks=loop.manager.gap_fallbacks, phase=runner.phase_name,
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


class _Signals:
    """SIGINT and SIGTERM: the first stops the loop smoothly, the second releases at once."""

    def __init__(self, operator: OperatorChannel):
        self.operator, self.loop, self.count = operator, None, 0

    def __call__(self, signum, frame) -> None:
        self.count += 1
        if self.count == 1:
            if self.loop is not None:
                self.loop.request_stop()
            else:
                self.operator.post("stop")
        else:
            self.operator.post("release")


def _task_file(files, name: str) -> str:
    """The file of task ``name``: ``tasks/NAME.toml`` of the config folder, else of the packaged defaults."""
    try:
        return str(files.path(f"tasks/{name}.toml"))
    except ConfigError as exc:
        raise ConfigError(f"task {name}: no such task file (a name of tasks/ in the config folder or the packaged "
                          f"defaults, a task file, or module:attribute): {exc}") from None


def main(args) -> int:
    from servotau.hal.log import LogWriter
    from servotau.hal.registry import open_backend, overrides_from_args

    if args.hold_timeout is not None and not args.hold_timeout >= 0:
        raise ControlError(f"--hold-timeout {args.hold_timeout}: expected >= 0 [s]")
    files = config_files(args, HAL, CONTROL, ESTIMATION)
    try:  # a task name comes from the --config folder, else the packaged tasks
        name = _task_file(files, args.task) if is_task_name(args.task) else args.task
        task = resolve_task(name, args.duration)
    except ConfigError as exc:
        print(f"servotau control: {exc}", file=sys.stderr)
        return 2
    threads_before = {t.ident for t in threading.enumerate()}
    backend = open_backend(hal_config(files), **overrides_from_args(args))
    operator = OperatorChannel()
    writer = stream = None
    signals = _Signals(operator)
    main_thread = threading.current_thread() is threading.main_thread()
    old = {s: signal.signal(s, signals) for s in (signal.SIGTERM, signal.SIGINT)} if main_thread else {}
    try:
        key = serve_operator(backend, operator)
        robot = getattr(backend, "robot_name", backend.info.name)
        hint = (f"servotau ctl reset|release --robot {robot} (query {key})" if key else "Ctrl-C to stop")
        if args.hold_timeout is not None:
            hint += f"; releasing by itself after {args.hold_timeout:g} s"
        offsets = load_ft_offsets(args.ft_offsets, backend.info) if args.ft_offsets else None
        rec = open_recording(args.rerun)
        stream = RerunStream(rec, backend.info.joint_names, backend.info.model_path, signals=args.rerun_signals,
                             ft_sensor_names=backend.info.ft_sensor_names,
                             robot_hz=args.rerun_robot_hz) if rec is not None else None
        writer = LogWriter(args.log, backend.info, metadata={"mode": args.mode or "task", "task": task.source},
                           realtime=_on_wall_clock(backend)) if args.log else None
        result = run_session(backend, task=task, mode=args.mode, stream=stream, writer=writer,
                             operator=operator, hold_timeout=args.hold_timeout, hint=hint, trip_at=args.trip_at,
                             ft_offsets=offsets, status=not args.quiet, save_ft_offsets=args.save_ft_offsets,
                             loop_ready=lambda loop: setattr(signals, "loop", loop),
                             control_path=files.path(CONTROL.name), estimator=torque_estimator(files, backend.info))
    except HalError as exc:
        print(f"servotau control: robot lost: {exc}", file=sys.stderr)
        return 4
    except (InfeasibleTask, ConfigError) as exc:
        print(f"servotau control: {exc}", file=sys.stderr)
        return 2
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
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
        how = {"released": "released: servotau ctl release or a second SIGTERM/Ctrl-C",
               "stopped": "stopped: servotau ctl stop, Ctrl-C or SIGTERM",
               "hold_timeout": "released after --hold-timeout"}
        print(f"safety trip: {result.tripped} ({how.get(result.end, result.end)}; {result.resets} resets)",
              file=sys.stderr)
        return 3
    if result.end == "stopped":
        print(f"servotau control: stopped in phase {result.phase}: the reference at rest, position mode")
        return 0
    if result.end != "completed":
        print(f"servotau control: released in phase {result.phase}, before the end of the task", file=sys.stderr)
        return 130
    return 0
