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
reference is sampled in robot time from its start. A phase without a length runs until the loop is stopped.
The reference is None after the last phase: the loop ends (``completed``). An operator's ``start`` (``servotau
ctl start TASK``) replaces the rest of the task: the reference comes to rest (jerk-limited), then the new
task's phases begin there (no settle phase: the filters are full, the offsets calibrated).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from servotau.errors import ConfigError, ServotauError
from servotau.hal.types import RobotInfo

from ..config import DEFAULT_PATH
from ..loop import ControlLoop, LoopHook, LoopResult, Tick
from ..manager import ControlManager
from ..trajectory import ForceCompatiblePosture, TrajectoryPoint, stopping_segment
from .build import Phase, Task, check_feasible, task_control_config, task_gains
from .plugin import resolve_task
from .references import Hold
from .spec import Wave

log = logging.getLogger(__name__)



class TaskRunner(LoopHook):
    """The loop's reference and hook for a task (module doc).

    Args:
        task: A :class:`~.build.Task` (a :class:`~.build.FileTask`, or a user's).
        info: The robot.
        control: config/control.toml (or another path) that the task's gains and force task override.
        resolve: Task name -> task, for the operator's ``start`` (default :func:`~.build.resolve_task`).
        progress: Called with a line of text at each phase's start.
    """

    def __init__(self, task: Task, info: RobotInfo, *, control=DEFAULT_PATH,
                 resolve: Callable[[str], Task] = resolve_task, progress: Callable[[str], None] | None = None):
        self.task, self.info, self.control_path = task, info, control
        self.resolve, self.progress = resolve, progress or (lambda _: None)
        self.phases: list[Phase] = []
        self.index = -1  # phase running (-1: settling)
        self.t_phase = 0.0  # [s] loop time at the phase's start
        self._manager: ControlManager | None = None
        self._gains: tuple[dict, object] | None = None
        self._f_meas: np.ndarray | None = None
        self._f0: np.ndarray | None = None
        self._compatible: ForceCompatiblePosture | None = None
        self._pending: list[Phase] | None = None  # an operator's new task, after the stop segment
        self._last: TrajectoryPoint | None = None

    # -- set-up ---------------------------------------------------------------------------------------
    @property
    def phase_name(self) -> str:
        if self.index < 0:
            return "settle"
        return self.phases[self.index].name if self.index < len(self.phases) else "done"

    def manager(self) -> ControlManager:
        """The controller with the task's gains and force task (config/control.toml otherwise)."""
        if self._manager is None:
            self._manager = ControlManager(self.info, self.control_config())
        return self._manager

    def control_config(self):
        phases = self.task.phases(self.info, np.zeros(self.info.nq)) if self._gains is None else None
        if self._gains is None:
            self._gains = task_gains(self.task, phases)
        gains, force = self._gains
        return task_control_config(self.info, gains, force, self.control_path, file=self.task.source)

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

    def prepare(self, q_start: np.ndarray) -> list[Phase]:
        """Build the phases on ``q_start`` and check them (raises :class:`~.build.InfeasibleTask`)."""
        phases = list(self.task.phases(self.info, np.array(q_start, dtype=float)))
        if not phases:
            raise ConfigError(f"{self.task.source}: no phase: expected at least one")
        for p in phases:
            if p.force is not None and p.mode != "torque":
                raise ConfigError(f'{self.task.source}: phase "{p.name}": a force task in a {p.mode} phase: expected '
                                  'mode = "torque"')
            if p.force is not None and p.force.posture == "compatible" and p.force.axes[:3] != ("fx", "fy", "fz"):
                raise ConfigError(f'{self.task.source}: phase "{p.name}": posture = "compatible" needs axes starting '
                                  f'with fx, fy, fz (got {list(p.force.axes)}): expected those, or posture = "start"')
        gains = task_gains(self.task, phases)
        if self._gains is not None and gains != self._gains:
            raise ConfigError(f"{self.task.source}: gains or force task {gains} differ from the run's {self._gains}: "
                              "expected the same (the controller's gains are fixed for a run)")
        check_feasible(self.task, phases, self.info, self.manager().config.safety)
        self.phases = phases
        return phases

    def run(self, loop: ControlLoop, **kwargs) -> LoopResult:
        """Check the task on the first frame, then run it on ``loop`` (``kwargs``: of :meth:`ControlLoop.run`)."""
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
                self.phases, self._pending = self._pending, None
                self._enter(0, tick)
                continue
            self._enter(self.index + 1, tick)
        if self._compatible is not None:
            idc = self.manager().law.inverse_dynamics
            point = self._compatible.update(t, tick.estimate.q, idc.task_jacobian, idc.f_hat[:3], idc.f_d[:3])
        else:
            point = p.reference.sample(t)
        self._last = point
        return point

    def _enter(self, index: int, tick: Tick) -> None:
        self.index, self.t_phase = index, tick.t
        self._compatible, self._f0 = None, None
        if index >= len(self.phases):
            return
        p = self.phases[index]
        manager = self.manager()
        if not manager.tripped:
            manager.request_mode(p.mode)
        if p.force is not None and p.force.posture == "compatible":
            joints = np.flatnonzero(manager.torque_mask)
            self._compatible = ForceCompatiblePosture(p.reference.q0, joints, p.force.calibration,
                                                      p.force.max_displacement)
        length = f"{p.length:.2f} s" if p.length is not None else "until stopped"
        self.progress(f"phase {index + 1}/{len(self.phases)} {p.name}: {p.mode} mode, {length}")

    def before_control(self, tick: Tick) -> None:
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
    def start_request(self, args: dict, tick: Tick) -> str | None:
        """``start`` a task (``args["task"]``: a name, file or import path) from where the reference comes to rest;
        returns None, or why it is refused (unknown task, infeasible, other gains)."""
        name = args.get("task")
        if not isinstance(name, str) or not name:
            return 'start: expected {"task": a task name, file or module:attribute}'
        if self.manager().tripped:
            return "start: a safety trip is latched: reset first"
        # from this tick's reference: the held posture after a reset, the start posture while settling
        last = tick.reference or self._last or TrajectoryPoint(tick.frame.q.copy(), np.zeros(self.info.nq),
                                                               np.zeros(self.info.nq))
        stop = stopping_segment(last.q, last.dq, last.ddq)
        margin = self.manager().config.safety.joint_limit_margin
        out = np.flatnonzero((stop.q1 < self.info.q_min + margin) | (stop.q1 > self.info.q_max - margin))
        if out.size:
            return (f"start {name}: the stop before it would carry {self.info.joint_names[out[0]]} to "
                    f"{stop.q1[out[0]]:.3f} rad, beyond its range with the {margin} rad margin")
        try:
            task = self.resolve(name)
            old, self.task = self.task, task
            try:
                phases = self.prepare(stop.q1)
            finally:
                self.task = old
        except ServotauError as exc:
            return f"start {name}: {exc}"
        self.task = task
        self.phases = [Phase("stop", _Segment(stop), "position" if not self._current_torque() else "torque")]
        self._pending = phases
        self._enter(0, tick)
        log.info("operator: task %s started", name)
        return None

    def _current_torque(self) -> bool:
        return self.manager().mode.value == "torque"


class _Segment(Hold):
    """A :class:`~.profile.JerkLimitedSegment` as a phase's reference."""

    def __init__(self, segment):
        super().__init__(segment.q0)
        self.segment, self.duration = segment, segment.duration

    def sample(self, t: float) -> TrajectoryPoint:
        return TrajectoryPoint(*self.segment.sample(t))
