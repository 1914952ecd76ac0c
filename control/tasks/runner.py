"""Runs a task on the control loop: the phases in sequence, each in its mode, with its force reference.

::

    runner = TaskRunner(FileTask.load("swing"), backend.info)
    loop = ControlLoop(backend, runner.manager(), hooks=[runner], settle=runner.task.settle,
                       ft_offsets=runner.ft_offsets())
    result = runner.run(loop)                         # or loop.run(runner.reference, None, actions=runner.actions)

:meth:`TaskRunner.prepare` builds the phases on the first frame's posture and checks them
(:func:`~.build.check_feasible`) before the loop writes its first command: an infeasible task raises
:class:`~.build.InfeasibleTask` and nothing is sent. The loop's settle phase comes first (position mode, the
start posture, F/T calibration), then each phase: its mode is requested on its first tick (bumpless), its
reference is sampled in robot time from its start. A torque phase's gains (its own, else control.toml's) replace the
previous ones in place over :data:`GAIN_RAMP` (:meth:`~..law.TorqueControlLaw.set_gains`: no step in the command; the
integrals keep their state). A phase without a length runs until the loop is stopped.
The reference is None after the last phase: the loop ends (``completed``). An operator's ``start`` (``servotau
ctl start TASK``) replaces the rest of the task: the reference comes to rest (jerk-limited), then the new
task's phases begin there (no settle phase: the filters are full, the offsets calibrated).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass

import numpy as np

from servotau.errors import ConfigError, ServotauError
from servotau.hal.types import RobotInfo

from ..config import DEFAULT_PATH
from ..loop import ControlLoop, Deferred, LoopHook, LoopResult, Tick, estimator_config
from ..manager import ControlManager
from ..trajectory import ForceCompatiblePosture, TrajectoryPoint, stopping_segment
from .build import Phase, PhaseGains, Task, check_feasible, phase_gains, task_control_config, task_force
from .lag import LagModel
from .plugin import resolve_task
from .references import Hold
from .spec import Wave

log = logging.getLogger(__name__)

GAIN_RAMP = 0.1  # [s] a torque phase's gains replace the previous phase's over this time from its start (law.py)
START_BUILD_LIMIT = 10.0  # [s] of robot time an operator's start may take to build; then it is refused



@dataclass(frozen=True)
class Plan:
    """A task built on a start posture and checked (:meth:`TaskRunner.build`): ready for the loop to run."""

    task: Task
    phases: tuple[Phase, ...]
    gains: tuple[PhaseGains | None, ...]  # per phase (None: a position phase)
    q_start: np.ndarray  # [rad] (n,) the posture it was built on


class TaskRunner(LoopHook):
    """The loop's reference and hook for a task (module doc).

    Args:
        task: A :class:`~.build.Task` (a :class:`~.build.FileTask`, or a user's).
        info: The robot.
        control: config/control.toml (or another path) that the task's gains and force task override.
        resolve: Task name -> task, for the operator's ``start`` (default :func:`~.build.resolve_task`).
        progress: Called with a line of text at each phase's start.
        shape: ``shape(tick, point) -> point``: applied to every point of the task's reference (not to the loop's
            holds and stops), e.g. a fault injection (``servotau control --trip-at``), or None.
    """

    def __init__(self, task: Task, info: RobotInfo, *, control=DEFAULT_PATH,
                 resolve: Callable[[str], Task] = resolve_task, progress: Callable[[str], None] | None = None,
                 shape: Callable[[Tick, TrajectoryPoint], TrajectoryPoint] | None = None):
        self.task, self.info, self.control_path = task, info, control
        self.resolve, self.progress, self.shape = resolve, progress or (lambda _: None), shape
        self.phases: list[Phase] = []
        self.gains: list[PhaseGains | None] = []
        self.index = -1  # phase running (-1: settling)
        self.t_phase = 0.0  # [s] loop time at the phase's start
        self._manager: ControlManager | None = None
        self._force: tuple | None = None  # (the run's force task,) once known
        self._gain_cache: dict = {}
        self._lag: LagModel | None = None  # used by build() only (one thread at a time)
        encoders = estimator_config().encoders
        self.encoders = (encoders.window, encoders.order)  # the estimator's encoder filter (run(): the loop's)
        self._f_meas: np.ndarray | None = None
        self._f0: np.ndarray | None = None
        self._compatible: ForceCompatiblePosture | None = None
        self._pending: Plan | None = None  # an operator's new task, after the stop segment
        self._job: _StartJob | None = None  # an operator's start being built off the loop's thread
        self._last: TrajectoryPoint | None = None

    # -- set-up ---------------------------------------------------------------------------------------
    @property
    def phase_name(self) -> str:
        if self.index < 0:
            return "settle"
        return self.phases[self.index].name if self.index < len(self.phases) else "done"

    def manager(self) -> ControlManager:
        """The controller with the task's force task (control.toml's gains; each torque phase sets its own)."""
        if self._manager is None:
            self._manager = ControlManager(self.info, self.control_config())
        return self._manager

    def control_config(self):
        if self._force is None:
            self._force = (task_force(self.task, self.task.phases(self.info, np.zeros(self.info.nq))),)
        return task_control_config(self.info, {}, self._force[0], self.control_path, file=self.task.source)

    def ft_offsets(self, given: Callable | None = None) -> Callable | None:
        """The loop's ``ft_offsets``: None (calibrate on the settle frames) or ``given``; a task whose F/T offsets
        are ``external`` needs ``given``.

        Raises:
            ConfigError: ``external`` offsets and none given.
        """
        if self.task.ft_offsets == "external" and given is None:
            raise ConfigError(f"{self.task.source}: settle.ft_offsets = \"external\": expected F/T offsets from the "
                              "caller (measured with the end effectors free, e.g. the robot hanging)")
        return given

    def build(self, task: Task, q_start: np.ndarray) -> Plan:
        """``task``'s phases on ``q_start`` (n,) [rad], checked (:func:`~.build.check_feasible`, the servo's lag),
        with the gains of each phase: everything before the loop may run it. The operator's ``start`` calls this on
        a worker thread, never on the loop's.

        Raises:
            InfeasibleTask: A phase leaves the robot's limits (naming the phase, the joint and the limit).
            ConfigError: The task cannot be built, or its gains or force task cannot be the controller's.
        """
        q_start = np.array(q_start, dtype=float)
        phases = list(task.phases(self.info, q_start))
        if not phases:
            raise ConfigError(f"{task.source}: no phase: expected at least one")
        for p in phases:
            if p.force is not None and p.mode != "torque":
                raise ConfigError(f'{task.source}: phase "{p.name}": a force task in a {p.mode} phase: expected '
                                  'mode = "torque"')
            if p.force is not None and p.force.posture == "compatible" and p.force.axes[:3] != ("fx", "fy", "fz"):
                raise ConfigError(f'{task.source}: phase "{p.name}": posture = "compatible" needs axes starting '
                                  f'with fx, fy, fz (got {list(p.force.axes)}): expected those, or posture = "start"')
        force = task_force(task, phases)
        config = self.manager().config
        if force is not None and (self._force is None or force != self._force[0]):
            raise ConfigError(f"{task.source}: force task {force} differs from the run's "
                              f"{self._force[0] if self._force else None}: expected the same (the controller's force "
                              "task is fixed for a run)")
        gains = phase_gains(task, phases, self.info, self.control_path, self._gain_cache, q_start)
        if self._lag is None:
            self._lag = LagModel(self.info, config.motors, config.base, self.encoders)
        check_feasible(task, phases, self.info, config.safety, self._lag)
        return Plan(task, tuple(phases), tuple(gains), q_start)

    def prepare(self, q_start: np.ndarray) -> list[Phase]:
        """Build the phases on ``q_start`` and check them (raises :class:`~.build.InfeasibleTask`)."""
        self._use(self.build(self.task, q_start))
        return self.phases

    def _use(self, plan: Plan, before: Sequence[Phase] = ()) -> None:
        self.task = plan.task
        self.phases = [*before, *plan.phases]
        self.gains = [None] * len(before) + list(plan.gains)

    def run(self, loop: ControlLoop, **kwargs) -> LoopResult:
        """Check the task on the first frame, then run it on ``loop`` (``kwargs``: of :meth:`ControlLoop.run`)."""
        encoders = loop.estimator.config.encoders
        if (encoders.window, encoders.order) != self.encoders:
            self.encoders, self._lag = (encoders.window, encoders.order), None
        self.prepare(loop.start().q)
        self.attach(loop)
        return loop.run(self.reference, None, actions=self.actions, **kwargs)

    def attach(self, loop: ControlLoop) -> None:
        """The loop's status detail says the task and the phase."""
        loop.describe = lambda: {"task": self.task.name, "phase": self.phase_name}

    @property
    def actions(self) -> dict:
        """The loop's extra operator actions: ``start`` (a new task)."""
        return {"start": self.start_request}

    # -- per tick -------------------------------------------------------------------------------------
    def reference(self, tick: Tick) -> TrajectoryPoint | None:
        if self.index < 0:
            self._enter(0, tick)
        while True:
            if self.index >= len(self.phases):
                return None
            p = self.phases[self.index]
            t = tick.t - self.t_phase
            if p.length is None or t < p.length - 1e-9:
                break
            if self._pending is not None:
                self._use(self._pending)
                self._pending = None
                self._enter(0, tick)
                continue
            if self._job is not None and self._job.stage == 2:  # at rest, the new task still being built
                break
            self._enter(self.index + 1, tick)
        if self._compatible is not None:
            idc = self.manager().law.inverse_dynamics
            point = self._compatible.update(t, tick.estimate.q, idc.task_jacobian, idc.f_hat[:3], idc.f_d[:3])
        else:
            point = p.reference.sample(t)
        if self.shape is not None:
            point = self.shape(tick, point)
        self._last = point
        return point

    def _enter(self, index: int, tick: Tick) -> None:
        self.index, self.t_phase = index, tick.t
        self._compatible, self._f0 = None, None
        if index >= len(self.phases):
            return
        p = self.phases[index]
        manager = self.manager()
        gains = self.gains[index] if index < len(self.gains) else None
        if gains is not None:  # ramped in torque mode, at once when the switch to torque fades the command
            manager.law.set_gains(gains.k_p, gains.k_s, gains.k_d, ramp=GAIN_RAMP)
        if not manager.tripped:
            manager.request_mode(p.mode)
        if p.force is not None and p.force.posture == "compatible":
            joints = np.flatnonzero(manager.torque_mask)
            self._compatible = ForceCompatiblePosture(p.reference.q0, joints, p.force.calibration,
                                                      p.force.max_displacement)
        length = f"{p.length:.2f} s" if p.length is not None else "until stopped"
        self.progress(f"phase {index + 1}/{len(self.phases)} {p.name}: {p.mode} mode, {length}")

    def before_control(self, tick: Tick) -> None:
        if self._job is not None:
            if self._job.result.done():
                self._adopt(tick)
            elif tick.t - self._job.t0 > START_BUILD_LIMIT:  # a build that hangs: refused, the worker is left
                self._refuse(self._job, f"not built within {START_BUILD_LIMIT:g} s of robot time")
        manager = self.manager()
        if manager.config.force is None or self._f_meas is None:
            return
        p = self.phases[self.index] if 0 <= self.index < len(self.phases) else None
        if p is None or p.force is None:
            manager.set_force_reference(self._f_meas)  # no regulation: the measured wrench
            return
        if self._f0 is None:
            self._f0 = self._f_meas.copy()
        t = tick.t - self.t_phase
        f_d = self._f0.copy()
        axes = ("fx", "fy", "fz", "tx", "ty", "tz")
        for axis, ref in p.force.reference.items():
            i = axes.index(axis)
            if isinstance(ref, Wave):
                f_d[i] = self._f0[i] + ref.amplitude * np.sin(2 * np.pi * ref.frequency * t)
            elif ref != "start":
                f_d[i] = float(ref)
        manager.set_force_reference(f_d)

    def on_tick(self, tick: Tick) -> None:
        if self.manager().config.force is not None:
            self._f_meas = np.array(tick.terms.f_hat, dtype=float)

    # -- operator ---------------------------------------------------------------------------------------
    def start_request(self, args: dict, tick: Tick) -> str | Deferred | None:
        """``start`` a task (``args["task"]``: a name, file or import path): the loop's thread only checks the
        request and hands it to a worker thread, which reads and builds the task (:meth:`build`) on the posture
        where the reference would come to rest; the answer follows once it is built (a :class:`Deferred`): a
        refusal (unknown task, infeasible, another force task) changes nothing. The new task starts from where the
        reference comes to rest, stopped at the tick the built task is taken; if the reference moved meanwhile,
        the task is built again on that rest posture while the reference comes to rest (refused then: the
        reference rests there, the old task is over)."""
        name = args.get("task")
        if not isinstance(name, str) or not name:
            return 'start: expected {"task": a task name, file or module:attribute}'
        if self.manager().tripped:
            return "start: a safety trip is latched: reset first"
        if self._job is not None:
            return f"start {name}: task {self._job.name} is being started: expected one start at a time"
        stop, refusal = self._stop_from(tick, name)
        if refusal is not None:
            return refusal
        self._job = _StartJob(name, stop.q1, Deferred(), tick.t)
        self._job.launch(lambda: self.build(self.resolve(name), stop.q1))
        return self._job.answer

    def _stop_from(self, tick: Tick, name: str):
        """The stop segment from this tick's reference (the held posture after a reset, the start while settling),
        or why it cannot be."""
        last = tick.reference or self._last or TrajectoryPoint(tick.frame.q.copy(), np.zeros(self.info.nq),
                                                               np.zeros(self.info.nq))
        stop = stopping_segment(last.q, last.dq, last.ddq)
        margin = self.manager().config.safety.joint_limit_margin
        out = np.flatnonzero((stop.q1 < self.info.q_min + margin) | (stop.q1 > self.info.q_max - margin))
        if out.size:
            return stop, (f"start {name}: the stop before it would carry {self.info.joint_names[out[0]]} to "
                          f"{stop.q1[out[0]]:.3f} rad, beyond its range with the {margin} rad margin")
        return stop, None

    def _adopt(self, tick: Tick) -> None:
        """The worker is done (loop thread): take the built task, build it again on a new rest posture, or refuse."""
        job = self._job
        if self.manager().tripped:  # tripped while it was being built: the hold stays until an operator acts
            self._job = None
            job.answer.finish(f"start {job.name}: a safety trip latched meanwhile: reset first")
            return
        try:
            plan = job.result.result()
        except ServotauError as exc:
            self._refuse(job, str(exc))
            return
        stop, refusal = self._stop_from(tick, job.name)
        if job.stage == 1 and refusal is not None:
            self._job = None
            job.answer.finish(refusal)
            return
        mode = "torque" if self.manager().mode.value == "torque" else "position"
        if job.stage == 1:
            self.phases, self.gains = [Phase("stop", _Segment(stop), mode)], []
            self._enter(0, tick)
        if job.stage == 2 or np.array_equal(stop.q1, job.q1):
            self._pending, self._job = plan, None
            job.answer.finish(None)
            log.info("operator: task %s started", job.name)
            return
        job.stage, job.q1, job.t0 = 2, stop.q1, tick.t  # the reference moved: built again where it now rests
        job.launch(lambda: self.build(plan.task, stop.q1))

    def _refuse(self, job: _StartJob, why: str) -> None:
        """Answer the operator's start with a refusal (loop thread); in stage 2 the reference rests where it
        stopped."""
        self._job = None
        if job.stage == 2:  # the reference is coming to rest: it stays there
            self.phases, self.gains = [*self.phases[:1], Phase("rest", Hold(job.q1), self.phases[0].mode)], []
            job.answer.finish(f"start {job.name}: {why} (the reference rests where it stopped)")
        else:
            job.answer.finish(f"start {job.name}: {why}")


class _StartJob:
    """An operator's ``start`` being built by a worker thread: stage 1 on the rest posture at the request, stage 2
    (if the reference moved) on the rest posture of the stop begun when stage 1 was done."""

    def __init__(self, name: str, q1: np.ndarray, answer: Deferred, t0: float):
        self.name, self.q1, self.answer, self.stage = name, q1, answer, 1
        self.t0 = t0  # [s] robot time the build of this stage began
        self.result: Future = Future()

    def launch(self, build: Callable[[], Plan]) -> None:
        self.result = Future()

        def work():
            try:
                self.result.set_result(build())
            except ServotauError as exc:
                self.result.set_exception(exc)
            except BaseException as exc:  # a user's task class: whatever it raises (SystemExit too) is a refusal
                self.result.set_exception(ConfigError(f"{type(exc).__name__}: {exc}"))

        threading.Thread(target=work, name=f"task-build {self.name}", daemon=True).start()


class _Segment(Hold):
    """A :class:`~.profile.JerkLimitedSegment` as a phase's reference."""

    def __init__(self, segment):
        super().__init__(segment.q0)
        self.segment, self.duration = segment, segment.duration

    def sample(self, t: float) -> TrajectoryPoint:
        return TrajectoryPoint(*self.segment.sample(t))
