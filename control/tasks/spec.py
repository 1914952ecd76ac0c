"""Task files (``config/tasks/*.toml``): a settle phase, then a sequence of phases, read into frozen dataclasses.

Every field is validated when the file is read; an error names the file, the phase and the field (``field
'phases.swing.reference.max_velocity' = -1: expected a finite number > 0 [rad/s]``). Joints are addressed by
name and checked against the robot when the task is built (:mod:`.build`). The format is in docs/control.md
("Tasks"); the shipped files are commented examples.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from servotau.config import CONFIG_DIR, Section, load_toml, resolve_config_path
from servotau.errors import ConfigError

from ..config import AXES

KINDS = ("hold", "sinusoid", "growing_sinusoid", "waypoints", "table")
MODES = ("position", "torque")
PROFILES = ("jerk_limited", "min_jerk")
GAIN_KEYS = ("k6", "k_s", "k7", "k_d", "k7_per_k_v", "k_p")
"""A phase's gains: the stiffness as k6 [-] or k_s [N m/rad]; the velocity gain as k7 [s], k_d [N m s/rad] or
k7_per_k_v [-] (k7 = k7_per_k_v k_v of each joint's motor model); k_p [-]."""
GAIN_GROUPS = (("k6", "k_s"), ("k7", "k_d", "k7_per_k_v"))
"""Forms of one gain: a phase gives at most one of each group, and it replaces control.toml's."""
V_MAX, A_MAX, J_MAX = 1.0, 5.0, 50.0  # [rad/s, rad/s^2, rad/s^3] default bounds of a jerk-limited move


@dataclass(frozen=True)
class Wave:
    """One joint's sinusoid about its phase-start angle: ``(a0 + a t) sin(2 pi f t + phase)``, the amplitude
    bounded by ``max_amplitude`` and faded in over ``ramp`` [s] (``a = 0``: a plain sinusoid)."""

    amplitude: float  # [rad] a0
    frequency: float  # [Hz]
    growth: float = 0.0  # [rad/s] a (the paper's increasing-amplitude excitation, section 3.4.2)
    max_amplitude: float = math.inf  # [rad]
    phase: float = 0.0  # [rad]
    ramp: float = 0.0  # [s]


@dataclass(frozen=True)
class Waypoint:
    """Targets [rad] by joint (``delta``: relative to the phase-start angle); ``at``: [s] from the phase start
    (min_jerk profile) or None (jerk_limited: as fast as the bounds allow)."""

    targets: Mapping[str, float]
    delta: Mapping[str, float]
    at: float | None = None
    start: bool = False  # back to the task's start posture (every joint)


@dataclass(frozen=True)
class ReferenceSpec:
    kind: str  # one of KINDS
    waves: Mapping[str, Wave] = field(default_factory=dict)
    waypoints: tuple[Waypoint, ...] = ()
    profile: str = "jerk_limited"
    max_velocity: float = V_MAX  # [rad/s]
    max_acceleration: float = A_MAX  # [rad/s^2]
    max_jerk: float = J_MAX  # [rad/s^3]
    table: str | None = None  # path of the trajectory table (CSV or Parquet)
    relative: bool = False  # table values are offsets [rad] from the phase-start posture
    joints: tuple[str, ...] = ()  # joints the table must have a column for


@dataclass(frozen=True)
class ForceSpec:
    """The force task of a phase (paper 5.4): the wrench of F/T ``sensor`` at ``frame`` + ``offset``, regulated on
    ``axes``; each axis' reference: a constant [N, N m], ``"start"`` (its value at the phase start) or a sinusoid
    about the start value (``{amplitude, frequency}``)."""

    sensor: str
    frame: str
    offset: tuple[float, float, float]
    axes: tuple[str, ...]
    k_f: tuple[float, ...]
    reference: Mapping[str, object]  # axis -> float | "start" | Wave
    posture: str = "compatible"  # joint reference: "compatible" (ForceCompatiblePosture) or "start"
    max_displacement: float = 0.01  # [m] of the compatible posture
    calibration: float = 2.0  # [s] of the compatible posture's compliance fit


@dataclass(frozen=True)
class PhaseSpec:
    name: str
    mode: str
    reference: ReferenceSpec
    duration: float | None = None  # [s]; None: the reference's own (waypoints, table) or until stopped
    gains: Mapping[str, float] = field(default_factory=dict)  # of GAIN_KEYS, for every torque joint
    force: ForceSpec | None = None


@dataclass(frozen=True)
class TaskSpec:
    """A task file: the settle phase, the phases, and which phase ``--duration`` sets."""

    name: str
    phases: tuple[PhaseSpec, ...]
    settle: float = 0.5  # [s] position mode holding the start posture (filters fill, F/T offsets calibrated)
    ft_offsets: str = "calibrate"  # "calibrate" on the settle frames (end effectors free) or "external" (caller's)
    description: str = ""
    duration_phase: str | None = None
    source: str = "<code>"


def is_task_name(name: str | Path) -> bool:
    """``name`` names a task of a config folder (``swing``), not a file (``my/task.toml``) nor a Python task
    (``mypkg.mytask:Task``)."""
    p = Path(name)
    return p.suffix != ".toml" and len(p.parts) == 1 and ":" not in str(name)


def task_path(name: str | Path) -> Path:
    """A task file: a path (as given), or a name of the packaged config/tasks (``swing`` ->
    config/tasks/swing.toml; never a file of the working folder: a config folder's tasks come by path,
    e.g. ``ConfigFiles.path("tasks/swing.toml")``)."""
    p = Path(name)
    if is_task_name(name):
        p = CONFIG_DIR / "tasks" / f"{name}.toml"
    try:
        return resolve_config_path(p)
    except ConfigError:
        raise ConfigError(f"task {name}: no such task file (a path, or a name of config/tasks/)") from None


def load_task(name: str | Path) -> TaskSpec:
    """Read and validate a task file (a path or a name of config/tasks/).

    Raises:
        ConfigError: Naming the file, the phase and the field.
    """
    path = task_path(name)
    root = load_toml(path)
    root.check_keys(["name", "description", "settle", "phases", "duration_phase", "version"])
    if "version" in root:
        root.int("version", min=1, max=1)
    settle = root.section("settle", {})
    settle.check_keys(["duration", "ft_offsets"])
    raw = root.data.get("phases")
    if not isinstance(raw, list) or not raw or not all(isinstance(p, Mapping) for p in raw):
        raise root.error("phases", raw if raw is not None else "missing", "an array of tables [[phases]], one or more")
    phases, names = [], set()
    for i, data in enumerate(raw):
        s = Section(data, root.file, f"phases[{i}]")
        name = s.str("name")
        if name in names:
            raise s.error("name", name, "a name not used by another phase")
        names.add(name)
        phases.append(_phase(Section(data, root.file, f"phases.{name}"), path.parent))
    duration_phase = root.str("duration_phase") if "duration_phase" in root else None
    if duration_phase is not None and duration_phase not in names:
        raise root.error("duration_phase", duration_phase, f"one of the phases {sorted(names)}")
    return TaskSpec(name=root.str("name", path.stem), phases=tuple(phases),
                    settle=settle.float("duration", 0.5, min=0.0, unit="s"),
                    ft_offsets=settle.str("ft_offsets", "calibrate", choices=("calibrate", "external")),
                    description=root.str("description", ""), duration_phase=duration_phase, source=str(path))


def _phase(s: Section, folder: Path) -> PhaseSpec:
    s.check_keys(["name", "mode", "duration", "reference", "force", *GAIN_KEYS])
    mode = s.str("mode", "position", choices=MODES)
    duration = s.float("duration", unit="s", min=0.0, strict_min=True) if "duration" in s else None
    gains = {k: s.float(k, min=0.0, unit={"k6": "-", "k7": "s", "k_s": "N m/rad", "k_d": "N m s/rad",
                                            "k7_per_k_v": "-", "k_p": "-"}[k]) for k in GAIN_KEYS if k in s}
    for group in GAIN_GROUPS:
        given = [k for k in group if k in gains]
        if len(given) > 1:
            raise s.error(given[1], gains[given[1]], f"one of {' or '.join(group)}, not {' and '.join(given)}")
    if gains and mode != "torque":
        key = next(iter(gains))
        raise s.error(key, gains[key], 'no gains in a position phase (mode = "torque" takes them)')
    ref = _reference(s.section("reference", {"type": "hold"}), folder)
    force = _force(s.section("force"), mode) if "force" in s else None
    if duration is None and ref.kind in ("sinusoid", "growing_sinusoid") and any(
            math.isinf(w.max_amplitude) and w.growth > 0 for w in ref.waves.values()):
        raise s.missing("duration", "a duration [s] (or max_amplitude on every growing joint)")
    return PhaseSpec(name=s.str("name"), mode=mode, reference=ref, duration=duration, gains=gains, force=force)


def _reference(s: Section, folder: Path) -> ReferenceSpec:
    kind = s.str("type", choices=KINDS)
    keys = {"hold": [], "sinusoid": ["joints"], "growing_sinusoid": ["joints"],
            "waypoints": ["waypoints", "profile", "max_velocity", "max_acceleration", "max_jerk"],
            "table": ["file", "relative", "joints"]}[kind]
    s.check_keys(["type", *keys])
    if kind in ("sinusoid", "growing_sinusoid"):
        joints = s.section("joints")
        if not joints.keys():
            raise s.error("joints", {}, "a table of joint name -> {amplitude, frequency, ...}")
        return ReferenceSpec(kind, waves={j: _wave(joints.section(j), kind) for j in joints.keys()})
    if kind == "waypoints":
        profile = s.str("profile", "jerk_limited", choices=PROFILES)
        raw = s.data.get("waypoints")
        if not isinstance(raw, list) or not raw or not all(isinstance(w, Mapping) for w in raw):
            raise s.error("waypoints", raw if raw is not None else "missing", "an array of tables [[...waypoints]]")
        points, last = [], 0.0
        for i, data in enumerate(raw):
            w = _waypoint(Section(data, s.file, f"{s.prefix}.waypoints[{i}]"), profile)
            if w.at is not None and not w.at > last:
                raise Section(data, s.file, f"{s.prefix}.waypoints[{i}]").error("at", w.at, f"> {last:g} [s]")
            last = w.at if w.at is not None else last
            points.append(w)
        bounds = {k: s.float(k, d, min=0.0, strict_min=True, unit=u) for k, d, u in
                  (("max_velocity", V_MAX, "rad/s"), ("max_acceleration", A_MAX, "rad/s^2"),
                   ("max_jerk", J_MAX, "rad/s^3"))}
        return ReferenceSpec(kind, waypoints=tuple(points), profile=profile, **bounds)
    if kind == "table":
        file = s.str("file")
        path = Path(file) if Path(file).is_absolute() else folder / file
        if not path.exists():
            raise s.error("file", file, f"an existing CSV or Parquet file (looked for {path})")
        if path.suffix.lower() not in (".csv", ".parquet"):
            raise s.error("file", file, "a .csv or .parquet file")
        joints = s.data.get("joints", [])
        if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
            raise s.error("joints", joints, "a list of joint names (the table's columns besides t)")
        return ReferenceSpec(kind, table=str(path), relative=s.bool("relative", False), joints=tuple(joints))
    return ReferenceSpec(kind)


def _wave(s: Section, kind: str) -> Wave:
    growing = kind == "growing_sinusoid"
    s.check_keys(["amplitude", "frequency", "phase", "ramp"] + (["growth", "max_amplitude"] if growing else []))
    return Wave(amplitude=s.float("amplitude", min=0.0, unit="rad"),
                frequency=s.float("frequency", min=0.0, strict_min=True, unit="Hz"),
                growth=s.float("growth", 0.0, min=0.0, unit="rad/s") if growing else 0.0,
                max_amplitude=s.float("max_amplitude", min=0.0, unit="rad") if growing and "max_amplitude" in s
                else math.inf,
                phase=s.float("phase", 0.0, unit="rad"), ramp=s.float("ramp", 0.0, min=0.0, unit="s"))


def _waypoint(s: Section, profile: str) -> Waypoint:
    at = None
    if profile == "min_jerk":
        at = s.float("at", min=0.0, strict_min=True, unit="s")
    elif "at" in s:
        raise s.error("at", s.data["at"], 'no "at" with profile = "jerk_limited" (time-optimal; "min_jerk" has '
                      "times)")
    start = s.bool("start", False)
    targets, delta = {}, {}
    for key in s.keys():
        if key in ("at", "start"):
            continue
        value = s.data[key]
        if isinstance(value, Mapping):
            d = Section(value, s.file, f"{s.prefix}.{key}")
            d.check_keys(["delta"])
            delta[key] = d.float("delta", unit="rad")
        else:
            targets[key] = s.float(key, unit="rad (or a table {delta = ...})")
    if start and (targets or delta):
        raise s.error("start", True, "start = true alone (the task's start posture), without joint targets")
    if not (start or targets or delta):
        raise s.error("start", "missing", "joint targets (NAME = angle or NAME = {delta = ...}) or start = true")
    return Waypoint(targets=targets, delta=delta, at=at, start=start)


def _force(s: Section, mode: str) -> ForceSpec:
    s.check_keys(["sensor", "frame", "offset", "axes", "k_f", "reference", "posture", "max_displacement",
                  "calibration"])
    if mode != "torque":
        raise s.error("sensor", s.data.get("sensor"), 'a force task only in a torque phase (mode = "torque")')
    axes = s.data.get("axes")
    if not isinstance(axes, list) or not axes or any(a not in AXES for a in axes) or len(set(axes)) != len(axes):
        raise s.error("axes", axes, f"a list of distinct axes among {list(AXES)}")
    k_f = s.floats("k_f", len(axes))
    if any(k < 0 for k in k_f):
        raise s.error("k_f", k_f, ">= 0 per axis")
    ref = s.section("reference")
    reference: dict[str, object] = {}
    for axis in ref.keys():
        if axis not in axes:
            raise ref.error(axis, ref.data[axis], f"a regulated axis, one of {axes}")
        v = ref.data[axis]
        if v == "start":
            reference[axis] = "start"
        elif isinstance(v, Mapping):
            w = ref.section(axis)
            w.check_keys(["amplitude", "frequency"])
            reference[axis] = Wave(w.float("amplitude", unit="N or N m"), w.float("frequency", min=0.0,
                                                                                   strict_min=True, unit="Hz"))
        else:
            reference[axis] = ref.float(axis, unit='N or N m (or "start", or {amplitude, frequency})')
    offset = s.floats("offset", 3, [0.0, 0.0, 0.0], unit="m")
    return ForceSpec(sensor=s.str("sensor"), frame=s.str("frame"), offset=tuple(offset), axes=tuple(axes),
                     k_f=tuple(k_f), reference=reference,
                     posture=s.str("posture", "compatible", choices=("compatible", "start")),
                     max_displacement=s.float("max_displacement", 0.01, min=0.0, strict_min=True, unit="m"),
                     calibration=s.float("calibration", 2.0, min=0.0, strict_min=True, unit="s"))
