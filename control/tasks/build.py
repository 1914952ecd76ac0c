"""From a task to what the loop runs: phases built on the start posture, checked against the robot's limits,
and the controller configuration the task asks for (its gains, its force task).

A task is any object with ``name`` and ``phases(info, q_start) -> Sequence[Phase]`` (:class:`Task`); a task
file is one (:class:`FileTask`). :func:`check_feasible` refuses a phase that would leave the joint limits (with
the safety margin), exceed the controller's velocity limit or last less than its trajectory needs, naming the
phase, the joint and the limit; the runner calls it after the first read and before the first command.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from servotau.config import load_toml, resolve_config_path
from servotau.errors import ConfigError, ControlError
from servotau.hal.types import RobotInfo

from ..config import DEFAULT_PATH, ControlConfig, SafetyLimits
from ..tuning import tuned
from .lag import VELOCITY_MARGIN, LagModel, check_lag
from .references import Hold, JerkLimited, JointReference, MinJerk, Sinusoids, Tabled, waypoint_targets
from .spec import GAIN_GROUPS, GAIN_KEYS, ForceSpec, TaskSpec, load_task
from .table import load_table

START_TOLERANCE = 0.01  # [rad] an absolute trajectory table must start this close to the posture at its phase
SHORT_SPEED = 2.5  # [rad/s] peak speed of a min-jerk phase in a shortened task (FileTask.shortened)


class InfeasibleTask(ControlError):
    """A task the robot cannot follow (beyond a joint limit, too fast, too short): refused before anything moves."""


@dataclass
class Phase:
    """One phase as the loop runs it: a joint reference in a control mode, for ``duration`` [s] (None: the
    reference's own; endless if it has none), with an optional force task (a torque phase only)."""

    name: str
    reference: JointReference
    mode: str = "position"
    duration: float | None = None
    force: ForceSpec | None = None
    gains: Mapping[str, float] = field(default_factory=dict)

    @property
    def length(self) -> float | None:
        """[s] how long the phase runs (None: until stopped)."""
        return self.duration if self.duration is not None else self.reference.duration


def ref_waypoints(p, ref: MinJerk):
    """The waypoints of ``p`` with the times ``ref`` was built with (scaled to the phase's duration)."""
    times = ref.traj.times[1:]
    return tuple(replace(w, at=float(t)) for w, t in zip(p.reference.waypoints, times, strict=True))


class Task:
    """What a task provides (user tasks implement :meth:`phases`; ``--task mypkg.mytask:Task``).

    ``phases(info, q_start)`` builds the phases on the start posture (n,) [rad]. The runner also calls it once
    with a zero posture before the first frame, to read the run's gains and force task (the controller is built
    before the robot is read): the gains must not depend on the posture.
    """

    name: str = "task"
    settle: float = 0.5  # [s] position mode at the start posture: filters fill, F/T offsets calibrated
    ft_offsets: str = "calibrate"  # "calibrate" (end effectors free while settling) or "external" (the caller's)
    source: str = "<code>"

    def phases(self, info: RobotInfo, q_start: np.ndarray) -> Sequence[Phase]:
        raise NotImplementedError


class FileTask(Task):
    """A task file (:mod:`.spec`), its phases built on the posture at the start."""

    def __init__(self, spec: TaskSpec):
        self.spec = spec
        self.name, self.settle, self.ft_offsets, self.source = spec.name, spec.settle, spec.ft_offsets, spec.source

    @classmethod
    def load(cls, name: str | Path, duration: float | None = None) -> FileTask:
        """``load_task(name)``; ``duration`` [s] replaces the duration of the task's ``duration_phase``."""
        spec = load_task(name)
        if duration is not None:
            if spec.duration_phase is None:
                raise ConfigError(f"{spec.source}: --duration {duration:g}: this task has no duration_phase to set")
            if not duration > 0:
                raise ConfigError(f"--duration {duration!r}: expected > 0 [s]")
            spec = replace(spec, phases=tuple(replace(p, duration=duration) if p.name == spec.duration_phase else p
                                              for p in spec.phases))
        return cls(spec)

    def shortened(self, seconds: float, settle: float | None = None) -> FileTask:
        """The task with every phase cut to at most ``seconds`` (quick runs, tests) and the settle phase to
        ``settle`` [s]: a jerk-limited phase keeps its time-optimal length, a min-jerk one the length at which its
        peak speed is :data:`SHORT_SPEED`, a table its own."""
        phases = tuple(replace(p, duration=min(p.duration, seconds))
                       if p.duration is not None and p.reference.kind != "waypoints" else p for p in self.spec.phases)
        out = FileTask(replace(self.spec, phases=phases, settle=self.spec.settle if settle is None else settle))
        out._short = seconds
        return out

    def phases(self, info: RobotInfo, q_start: np.ndarray) -> list[Phase]:
        out, q0 = [], np.array(q_start, dtype=float)
        for p in self.spec.phases:
            ref = self._reference(p, info, q0, q_start)
            duration = p.duration
            if isinstance(ref, MinJerk) and duration is not None:
                ref = self._reference(replace(p, reference=replace(p.reference, waypoints=tuple(
                    replace(w, at=w.at * duration / ref.duration) for w in p.reference.waypoints))), info, q0,
                    q_start)
                duration = None
            short = getattr(self, "_short", None)
            if isinstance(ref, MinJerk) and short is not None:
                peak = float(ref.envelope(None)[2].max())
                scale = min(1.0, max(short, ref.duration * peak / SHORT_SPEED) / ref.duration)
                ref = self._reference(replace(p, reference=replace(p.reference, waypoints=tuple(
                    replace(w, at=w.at * scale) for w in ref_waypoints(p, ref)))), info, q0, q_start)
            if isinstance(ref, JerkLimited) and short is not None and duration is not None:
                duration = max(duration, ref.optimal)
            phase = Phase(p.name, ref, p.mode, duration, p.force, dict(p.gains))
            out.append(phase)
            if not (p.force is not None and p.force.posture == "compatible"):  # else: near q0 (max_displacement)
                q0 = ref.sample(phase.length).q.copy() if phase.length is not None else ref.end
        return out

    def _reference(self, p, info: RobotInfo, q0: np.ndarray, q_task: np.ndarray) -> JointReference:
        r, names = p.reference, info.joint_names
        where = f'{self.source}: phase "{p.name}"'
        for j in [*r.waves, *(k for w in r.waypoints for k in (*w.targets, *w.delta))]:
            if j not in names:
                raise ConfigError(f'{where}: joint "{j}" is not a joint of the robot: expected one of {list(names)}')
        if r.kind in ("sinusoid", "growing_sinusoid"):
            return Sinusoids(q0, names, r.waves)
        if r.kind == "waypoints":
            targets = waypoint_targets(r, q0, names, q_task)
            if r.profile == "min_jerk":
                return MinJerk(q0, names, [(w.at, dict(zip(names, q, strict=True)))
                                           for w, q in zip(r.waypoints, targets, strict=True)])
            return JerkLimited(q0, targets, r.max_velocity, r.max_acceleration, r.max_jerk,
                               p.duration if p.duration is not None else 0.0)
        if r.kind == "table":
            try:
                table = load_table(r.table, names, r.joints)
            except ConfigError as exc:
                raise ConfigError(f"{where}: {exc}") from None
            return Tabled(q0, names, table, r.relative)
        return Hold(q0)


def check_feasible(task: Task, phases: Sequence[Phase], info: RobotInfo, limits: SafetyLimits,
                   lag: LagModel | None = None) -> None:
    """Refuse phases beyond the joint limits (``q_min + margin``, ``q_max - margin``), shorter than their
    trajectory, faster than ``(1 - VELOCITY_MARGIN[mode]) limits.max_velocity`` (with ``lag``: the speed the estimator
    will read, the servo's response through its filter) or (with ``lag``) needing a torque or a command error beyond
    the safety's (:mod:`.lag`).

    Raises:
        InfeasibleTask: Naming the task's file, the phase, the joint and the limit.
    """
    names, margin = info.joint_names, limits.joint_limit_margin
    lo_lim, hi_lim = info.q_min + margin, info.q_max - margin
    before: Phase | None = None
    for p in phases:
        where = f'{task.source}: phase "{p.name}"'
        ref = p.reference
        if before is not None and before.length is not None and not (
                before.force is not None and before.force.posture == "compatible"):
            jump = np.abs(ref.sample(0.0).q - before.reference.sample(before.length).q)
            if jump.max() > START_TOLERANCE:
                i = int(np.argmax(jump))
                raise InfeasibleTask(f'{where} starts {jump[i]:.3f} rad away from where phase "{before.name}" ends on '
                                     f"{names[i]}: expected within {START_TOLERANCE} rad (a reference without jumps)")
        before = p
        if isinstance(ref, JerkLimited) and p.duration is not None and p.duration < ref.optimal - 1e-9:
            raise InfeasibleTask(f"{where}: duration {p.duration:g} s is shorter than its time-optimal trajectory "
                                 f"({ref.optimal:.3f} s within max_velocity, max_acceleration, max_jerk): expected "
                                 f">= {ref.optimal:.3f} s")
        if isinstance(ref, Tabled) and p.duration is not None and p.duration < ref.duration - 1e-9:
            raise InfeasibleTask(f"{where}: duration {p.duration:g} s is shorter than its table {ref.table.file} "
                                 f"({ref.duration:g} s): expected >= {ref.duration:g} s, or no duration")
        if isinstance(ref, Tabled):
            jump = np.abs(ref.first - ref.q0[ref.index])
            if jump.max() > START_TOLERANCE:
                j = int(np.argmax(jump))
                raise InfeasibleTask(f'{where}: the table {ref.table.file} starts {jump[j]:.3f} rad away from the '
                                     f"posture at the phase start on {ref.table.joints[j]}: expected within "
                                     f"{START_TOLERANCE} rad (move there first with a waypoints phase)")
        lo, hi, v = ref.envelope(p.length)
        for arr, lim, cmp, what in ((lo, lo_lim, np.less, "lower"), (hi, hi_lim, np.greater, "upper")):
            bad = np.flatnonzero(cmp(arr, lim))
            if bad.size:
                i = int(bad[0])
                raise InfeasibleTask(f"{where}: joint {names[i]} reaches {arr[i]:.3f} rad, beyond its {what} limit "
                                     f"{lim[i]:.3f} rad (q_{'min' if what == 'lower' else 'max'} "
                                     f"{'+' if what == 'lower' else '-'} joint_limit_margin {margin:g} rad)")
        pred = lag.predict(ref, p.length) if lag is not None and p.force is None else None
        v_hat = v if pred is None else np.maximum(v, pred.velocity)
        v_margin = VELOCITY_MARGIN[p.mode]
        v_lim = (1.0 - v_margin) * limits.max_velocity
        over = np.flatnonzero(v_hat > v_lim)
        if over.size:
            i = int(over[np.argmax(v_hat[over] / v_lim[over])])
            need = ""
            if isinstance(ref, MinJerk):
                at_least = np.ceil(100 * ref.duration * v_hat[i] / v_lim[i]) / 100
                need = f": expected a duration of at least {at_least:.2f} s"
            read = f" (the estimator reads {v_hat[i]:.2f} rad/s: the servo's response through its filter)" \
                if v_hat[i] > v[i] + 0.005 else ""
            raise InfeasibleTask(f"{where}: joint {names[i]} moves at {v[i]:.2f} rad/s{read}, above {v_lim[i]:.2f} "
                                 f"rad/s = (1 - {v_margin:g}, {p.mode} mode) x the velocity limit "
                                 f"{limits.max_velocity[i]:g} rad/s (control.toml [safety] max_velocity){need}")
        refusal = check_lag(where, pred, info, limits) if pred is not None else None
        if refusal is not None:
            raise InfeasibleTask(refusal)


def task_force(task: Task, phases: Sequence[Phase]) -> ForceSpec | None:
    """The force task of the run: every force phase names the same sensor, frame, axes and k_f (the controller's
    force task is built once, with the controller).

    Raises:
        ConfigError: Two phases disagree (naming both).
    """
    force, fp = None, None
    for p in phases:
        if p.force is not None:
            key = (p.force.sensor, p.force.frame, p.force.offset, p.force.axes, p.force.k_f)
            if fp is not None and key != fp[1]:
                raise ConfigError(f'{task.source}: phase "{p.name}": force task {key} differs from phase "{fp[0]}"\'s: '
                                  "expected one force task per run")
            force, fp = p.force, fp or (p.name, key)
    return force


@dataclass(frozen=True)
class PhaseGains:
    """The gains a torque phase runs with, each (n,), 0 on position-controlled joints (:meth:`TorqueControlLaw.
    set_gains`)."""

    k_p: np.ndarray  # [-]
    k_s: np.ndarray  # [N m/rad]
    k_d: np.ndarray  # [N m s/rad]


def check_phase_gains(task: Task, p: Phase) -> None:
    """A phase's ``gains``: keys among :data:`~.spec.GAIN_KEYS` (not both forms of one gain), finite numbers >= 0,
    in a torque phase only (a task class may set anything; a task file is checked when read).

    Raises:
        ConfigError: Naming the task, the phase and the gain.
    """
    where = f'{task.source}: phase "{p.name}"'
    for key, value in dict(p.gains).items():
        if key not in GAIN_KEYS:
            raise ConfigError(f"{where}: gain {key!r}: expected one of {list(GAIN_KEYS)}")
        if isinstance(value, bool) or not isinstance(value, int | float) or not (math.isfinite(value) and value >= 0):
            raise ConfigError(f"{where}: gain {key} = {value!r}: expected a finite number >= 0")
    for group in GAIN_GROUPS:
        given = [k for k in group if k in p.gains]
        if len(given) > 1:
            raise ConfigError(f"{where}: gains {' and '.join(given)}: expected one of {' or '.join(group)}")
    if p.gains and p.mode != "torque":
        raise ConfigError(f'{where}: gains {dict(p.gains)} in a {p.mode} phase: expected mode = "torque" (or no gains)')


def phase_gains(task: Task, phases: Sequence[Phase], info: RobotInfo, path: str | Path = DEFAULT_PATH,
                cache: dict | None = None, posture=None) -> list[PhaseGains | None]:
    """The gains of each phase (None for a position phase): control.toml's (``path``) with the phase's ``gains`` on
    top, converted per joint as the file's own are (k6, k7, k7_per_k_v, k7_scaling), k_p scheduled and the loop
    checked at ``posture`` [rad] (:func:`task_control_config`). ``cache``: gain sets already converted (by their
    items and the posture to 1 mrad), kept between calls.

    Raises:
        ConfigError: A gain the controller refuses, naming the task, the phase, and the file's field or the joint.
    """
    cache = {} if cache is None else cache
    out: list[PhaseGains | None] = []
    for p in phases:
        check_phase_gains(task, p)
        if p.mode != "torque":
            out.append(None)
            continue
        key = (tuple(sorted(dict(p.gains).items())),
               None if posture is None else np.round(np.asarray(posture, dtype=float), 3).tobytes())
        if key not in cache:
            try:
                config = task_control_config(info, dict(p.gains), None, path, file=f'{task.source} phase "{p.name}"',
                                             posture=posture)
            except (ConfigError, ControlError) as exc:
                raise ConfigError(f'{task.source}: phase "{p.name}": gains {dict(p.gains)}: {exc}') from None
            g = PhaseGains(*(config.joint_vector(k) for k in ("k_p", "k_s", "k_d")))
            bad = [(j, k) for k in ("k_p", "k_s", "k_d") for j, v in zip(info.joint_names, getattr(g, k), strict=True)
                   if not math.isfinite(v)]
            if bad:
                raise ConfigError(f'{task.source}: phase "{p.name}": joint {bad[0][0]}: {bad[0][1]} is not finite: '
                                  "expected finite gains")
            cache[key] = g
        out.append(cache[key])
    return out


def task_control_config(info: RobotInfo, gains: Mapping[str, float], force: ForceSpec | None,
                        path: str | Path = DEFAULT_PATH, *, file: str = "", posture=None) -> ControlConfig:
    """config/control.toml (or ``path``) with ``gains`` for every torque joint and the ``force`` task; k_p scheduled
    from the identified model's margin at ``posture`` (n,) [rad] (None: the model's neutral posture) when the file
    says ``gain_schedule = "margin"``, then the predicted loop checked (control/tuning.py).

    Raises:
        ConfigError: The file or the gains are refused; :class:`~..tuning.UnstableLoopError` when the identified
            model predicts an unstable torque loop (naming the motor file, the joint and the gains).
    """
    root = load_toml(path)
    data = copy.deepcopy(dict(root.data))
    if isinstance(data.get("motors"), str):  # next to the file read (from_mapping knows no file to look beside)
        try:
            data["motors"] = str(resolve_config_path(data["motors"], root.file))
        except ConfigError:
            pass  # from_mapping names the field and the places looked
    if gains:
        defaults = data.setdefault("defaults", {})
        for key, value in gains.items():  # the phase's form of a gain replaces every form of it in the file
            group = next((g for g in GAIN_GROUPS if key in g), (key,))
            for table in (defaults, *data.get("joints", {}).values()):
                for k in group:
                    table.pop(k, None)
                if group == GAIN_GROUPS[1]:  # a phase's velocity gain is the one it runs with (no K6 scaling)
                    table.pop("k7_scaling", None)
            defaults[key] = value
            if group == GAIN_GROUPS[1]:
                defaults["k7_scaling"] = "constant"
    if force is not None:
        data["force"] = {"sensor": force.sensor, "frame": force.frame, "offset": list(force.offset),
                         "axes": list(force.axes), "k_f": list(force.k_f)}
    label = f"{root.file} with the gains of {file or 'the task'}" if gains or force is not None else root.file
    return tuned(ControlConfig.from_mapping(data, info, file=label), info, str(data.get("motors")), posture)
