"""The experiments' shared set-up: one simulated run (:func:`simulate`) on the control loop, its records
(:class:`Run`), the config overrides of a run and the output helpers (tables, figures).

Every run is deterministic: in-process lock-step backend, fixed seed. It runs
:class:`~servotau.control.loop.ControlLoop`: the settle phase in position mode (F/T offsets calibrated), the
run's mode, ``HOLD`` s holding the start posture, then the motion or force task, evaluated on the simulator's
ground truth.
"""

from __future__ import annotations

import copy
import csv
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from servotau.control.loop import SETTLE, LoopHook, Tick

log = logging.getLogger(__name__)

LEG = tuple(f"RLEG_JOINT{i}" for i in range(6))
LEG_LABELS = ("hip yaw", "hip roll", "hip pitch", "knee", "ankle pitch", "ankle roll")
PAPER_COMPONENTS = ("ff_torque", "ff_friction", "fb_position", "fb_velocity", "fb_acceleration", "fb_force")
OTHER_COMPONENTS = ("ff_extra", "fb_torque_residual", "fb_integral", "fb_position_integral", "switch_offset")

WORKBENCH_MODEL = "motors/hrp2_sim_improved.toml"  # the workbench's model, without the dead band measured on holds
PAPER_MODEL = "motors/hrp2_sim_identified.toml"  # the paper's motor model (k_tau, k_v), for comparison
# Runs beside the motion sweep and the force run, each one change from the config (label -> simulate() overrides)
VARIANTS = {"workbench model": {"motors": WORKBENCH_MODEL}, "paper model": {"motors": PAPER_MODEL},
            "ff=estimate": {"velocity_feedforward": "estimate"}}
HOLD = 1.0  # [s] in the experiment's mode before the motion (the mode switch offset fades in 0.5 s)
TAIL = 0.5  # [s] after the swing, still evaluated
SWING = 3.0  # [s] right_leg_swing duration (paper: stairs-climbing swing)
SEED = 0

# The force task (paper 5.4), as the runs set it up; the force experiment (force.py) chooses its reference.
FORCE_FREQUENCY = 0.5  # [Hz] of the reference sinusoid (the compatible posture refits once per period)
FORCE_KF = 1.0
# Regulated axes of the sole wrench. The paper (5.4) regulates the force, other force axes at zero; the moments
# are held at their value at the start of the task too (the centre of pressure stays where the foot settled): left
# free, they drift with the motor model's errors until the foot tips on the block's edge (docs/results.md, column
# 'forces only').
FORCE_AXES = ("fx", "fy", "fz", "tx", "ty")
FORCE_MAX_DISPLACEMENT = 0.01  # [m] the compatible posture follows the foot up to 1 cm from the start, per axis


# -- one simulated run ---------------------------------------------------------------------------------------
@dataclass
class Run:
    """Per-tick records of one run, right-leg columns only (from the start of the evaluated phase on)."""

    name: str
    time: list = field(default_factory=list)  # [s]
    q_ref: list = field(default_factory=list)  # [rad]
    q_true: list = field(default_factory=list)  # [rad] ground truth
    tau_hat: list = field(default_factory=list)  # [N m] estimator
    tau_true: list = field(default_factory=list)  # [N m] ground truth
    components: dict = field(default_factory=dict)  # name -> list of (6,) [rad]
    f_ref: list = field(default_factory=list)  # [N] (3,) force-task reference
    f_hat: list = field(default_factory=list)  # [N] (3,) measured, offset-compensated, at the task frame
    f_true: list = field(default_factory=list)  # [N] (3,) true total contact force on the right sole, world frame
    tripped: str | None = None

    def arrays(self) -> dict[str, np.ndarray]:
        out = {k: np.asarray(getattr(self, k), dtype=float) for k in
               ("time", "q_ref", "q_true", "tau_hat", "tau_true", "f_ref", "f_hat", "f_true")}
        out.update({k: np.asarray(v, dtype=float) for k, v in self.components.items()})
        return out


def control_config(info, k6: float | None, force_axes: tuple[str, ...], k7: float | None = None,
                   motors: str | None = None, velocity_feedforward: str | None = None, k_iq: float | None = None,
                   posture=None):
    """config/control.toml with every torque joint at ``k6`` (and ``k7`` [s], ``k_iq`` [1/s] if given), the motor
    file ``motors`` and the ``velocity_feedforward`` if given and, with ``force_axes``, the paper's force task on
    those axes; k_p scheduled from the identified model's margin at ``posture`` [rad] (the start posture) when the
    config says ``gain_schedule = "margin"``, then checked (control/tuning.py)."""
    from servotau.config import CONFIG_DIR, load_toml
    from servotau.control import ControlConfig
    from servotau.control.tuning import tuned

    data = copy.deepcopy(load_toml(CONFIG_DIR / "control.toml").data)

    def every_joint(values: dict, drop: tuple[str, ...] = ()) -> None:
        """``values`` in [defaults] for every torque joint: ``drop`` (the same gain in another unit) removed there,
        and no per-joint table keeps either."""
        for key in drop:
            data["defaults"].pop(key, None)
        data["defaults"].update(values)
        for joint in data.get("joints", {}).values():
            for key in (*values, *drop):
                joint.pop(key, None)

    if k6 is not None:
        every_joint({"k6": k6}, drop=("k_s",))
    if k7 is not None:  # a constant velocity gain for the whole run
        every_joint({"k7": k7, "k7_scaling": "constant"}, drop=("k_d", "k7_per_k_v"))
    if k_iq is not None:
        every_joint({"k_iq": k_iq})
    if motors is not None:
        data["motors"] = motors
    if velocity_feedforward is not None:
        data["velocity_feedforward"] = velocity_feedforward
    if force_axes:
        data["force"] = {"sensor": "right_ankle", "frame": "ft_right_ankle", "offset": [0.0, 0.0, -0.02],
                         "axes": list(force_axes), "k_f": [FORCE_KF] * len(force_axes)}
    config = ControlConfig.from_mapping(data, info, file="config/control.toml (experiment overrides)")
    return tuned(config, info, str(data["motors"]), posture)  # before anything moves


def motors_file() -> str:
    """The motor-parameter file of config/control.toml (relative to config/)."""
    from servotau.config import CONFIG_DIR, load_toml

    return str(load_toml(CONFIG_DIR / "control.toml").data["motors"])


def sim_config(scenario: str, seed: int, servo: str | None = None):
    """The simulator's config: ``config/scenarios/<scenario>.toml``, ``seed`` and the servo file ``servo`` (None:
    config/servo.toml)."""
    from servotau.config import resolve_config_path
    from servotau.simrobot.sim import SimConfig

    extra = {} if servo is None else {"servo_path": resolve_config_path(servo)}
    return SimConfig.named(scenario, seed=seed, **extra)


def ft_offsets_hanging(seed: int, est_cfg, servo: str | None = None) -> np.ndarray:
    """F/T offsets calibrated with the robot hanging, feet free (the paper's practice before lowering it).

    The simulated sensor offsets are drawn from the seed, so the same seed's hanging robot has the same sensors.
    """
    from servotau.estimation import calibrate_ft_offsets
    from servotau.simrobot.sim import SimRobot

    robot = SimRobot(sim_config("hanging", seed, servo))
    frames = []
    for _ in range(int(SETTLE / robot.period)):
        frames.append(robot.read())
        robot.step(robot.read().q)
    return calibrate_ft_offsets(frames, robot.info, est_cfg)


class _Task:
    """Task time [s] of a loop tick: from the start of the motion / force task (``HOLD`` s after the settle phase)."""

    def __init__(self, loop):
        self.dt = loop.info.period
        self.settle_ticks, self.hold_ticks = loop.settle_ticks, int(round(HOLD / self.dt))

    def time(self, tick: Tick) -> float:
        return (tick.k - self.settle_ticks - self.hold_ticks) * self.dt


class _Reference:
    """The swing (if any) from the task's start, else the start posture; with a force task and ``compatible``, the
    force-compatible posture (calibrated on the first period, not evaluated, then used)."""

    def __init__(self, task: _Task, hold, swing, compatible, manager):
        self.task, self.hold, self.swing, self.compatible, self.manager = task, hold, swing, compatible, manager

    def __call__(self, tick: Tick):
        t = self.task.time(tick)
        ref = self.swing.sample(t) if self.swing is not None and t >= 0 else self.hold
        if self.compatible is not None and t >= 0:
            idc = self.manager.law.inverse_dynamics
            ref = self.compatible.update(t, tick.estimate.q, idc.task_jacobian, idc.f_hat[:3], idc.f_d[:3])
        return ref


class _ForceReference(LoopHook):
    """The force task's reference before each control tick: the measured wrench of the last tick before the task
    (no regulation), then ``profile(t, f0)`` on the force and the moments held at their start value ``f0[3:]``
    (the centre of pressure stays where the foot settled)."""

    def __init__(self, task: _Task, manager, profile):
        self.task, self.manager, self.profile = task, manager, profile
        self.f_meas, self.f0 = None, None

    def before_control(self, tick: Tick) -> None:
        if self.f_meas is None:
            return
        t = self.task.time(tick)
        if t >= 0 and self.f0 is None:
            self.f0 = self.f_meas.copy()
        f_d = self.f_meas.copy() if t < 0 else np.concatenate([self.profile(t, self.f0[:3]), self.f0[3:]])
        self.manager.set_force_reference(f_d)

    def on_tick(self, tick: Tick) -> None:
        self.f_meas = np.array(tick.terms.f_hat, dtype=float)


class _Recorder(LoopHook):
    """The evaluated phase (task time >= 0) into ``run``: right-leg references, true angles and torques, estimated
    torques, command components and, with a force task, the task's forces."""

    wants_truth = True

    def __init__(self, run: Run, task: _Task, legs: np.ndarray, force: bool):
        self.run, self.task, self.legs, self.force = run, task, legs, force

    def on_tick(self, tick: Tick) -> None:
        t = self.task.time(tick)
        if t < 0:
            return
        run, legs, terms, truth = self.run, self.legs, tick.terms, tick.truth
        run.time.append(t)
        run.q_ref.append(tick.reference.q[legs])
        run.q_true.append(truth.q[legs])
        run.tau_hat.append(np.asarray(tick.estimate.tau)[legs])
        run.tau_true.append(truth.tau[legs])
        for c in PAPER_COMPONENTS + OTHER_COMPONENTS:
            run.components.setdefault(c, []).append(np.asarray(getattr(terms, c))[legs])
        if self.force:
            run.f_ref.append(np.array(terms.f_d[:3], dtype=float))
            run.f_hat.append(np.array(terms.f_hat[:3], dtype=float))
            run.f_true.append(truth.sole_contact_forces[0].copy())


def simulate(name: str, *, scenario: str = "hanging", mode: str = "torque", k6: float | None = 1.0,
             swing: float | None = SWING, force_profile=None, duration: float | None = None, seed: int = SEED,
             rerun: str | None = None, posture: str = "compatible", k7: float | None = None,
             motors: str | None = None, velocity_feedforward: str | None = None, k_iq: float | None = None,
             force_axes: tuple[str, ...] = FORCE_AXES, servo: str | None = None) -> Run:
    """One run: settle in position mode, switch to ``mode``, hold ``HOLD`` s, then the motion or force task.

    Args:
        name: Run label.
        scenario: ``hanging`` (motion) or ``force`` (right foot on the block).
        mode: ``position`` or ``torque``.
        k6: Position gain of the torque joints as a fraction of the native servo's (None: the config's).
        swing: Duration [s] of ``right_leg_swing``; None holds the start posture.
        force_profile: ``f(t) -> (3,)`` force reference [N] at the task frame, t from the task start, given the
            measured force at the start (``f0``) as ``f(t, f0)``; enables the force task.
        duration: Evaluated duration [s] (default: swing + TAIL).
        seed: Simulator seed.
        rerun: ``save:FILE`` etc. to stream the run to Rerun, or None.
        k7: Velocity gain [s] of the torque joints (None: the config's).
        motors: Motor-parameter file relative to config/ (None: the config's).
        velocity_feedforward: ``estimate`` or ``reference`` velocity in the motor-model feedforward (None: the
            config's).
        k_iq: Position-integral rate [1/s] of the torque joints (None: the config's; 0: off).
        force_axes: Regulated axes of the force task.
        servo: Servo config file of the simulated robot (None: config/servo.toml).
        posture: With a force task, the joint reference: ``compatible`` follows the measured motion along the
            task directions (:class:`~servotau.control.trajectory.ForceCompatiblePosture`, paper 5.4), ``start``
            is the start posture.
    """
    from servotau.control import ControlManager
    from servotau.control.loop import ControlLoop, estimator_config
    from servotau.control.trajectory import ForceCompatiblePosture, right_leg_swing
    from servotau.control.tuning import UnstableLoopError
    from servotau.estimation import TorqueEstimator
    from servotau.hal.backends.inprocess import InProcessBackend
    from servotau.simrobot.sim import SimRobot

    if posture not in ("compatible", "start"):
        raise ValueError(f"posture = {posture!r}: expected 'compatible' or 'start'")
    robot = SimRobot(sim_config(scenario, seed, servo))
    start_q = robot.read().q.copy()  # the start posture (read without a step)
    backend = InProcessBackend(robot)
    info = backend.info
    legs = np.array([info.joint_names.index(j) for j in LEG])
    est_cfg = estimator_config()
    try:  # the motor file and gains are checked before anything moves
        manager = ControlManager(info, control_config(info, k6, force_axes if force_profile is not None else (), k7,
                                                      motors, velocity_feedforward, k_iq, start_q))
    except UnstableLoopError as err:  # refused before anything moved: a run without records, counted as a trip
        backend.close()
        log.warning("%s: refused: %s", name, err)
        return Run(name, tripped=f"refused before moving: {err}")
    except BaseException:
        backend.close()
        raise
    # hanging: the feet touch nothing while settling; otherwise calibrate on the same robot hanging
    offsets = None if scenario == "hanging" else (lambda frames: ft_offsets_hanging(seed, est_cfg, servo))
    loop = ControlLoop(backend, manager, TorqueEstimator(info, est_cfg), mode=mode, ft_offsets=offsets)
    task, run = _Task(loop), Run(name)
    hooks = [_Recorder(run, task, legs, force_profile is not None)]
    if force_profile is not None:
        hooks.insert(0, _ForceReference(task, manager, force_profile))
    stream = None
    try:
        if rerun:
            from servotau.apps.control import RerunHook
            from servotau.apps.viewer import RerunStream, open_recording

            rec = open_recording(rerun, app_id=f"servotau-{name}")
            if rec is not None:
                stream = RerunStream(rec, info.joint_names, info.model_path)
                hooks.append(RerunHook(stream, info.ft_sensor_names))
        loop.hooks = tuple(hooks)
        q_start = loop.start().q.copy()
        compatible = (ForceCompatiblePosture(q_start, legs, 1.0 / FORCE_FREQUENCY, FORCE_MAX_DISPLACEMENT)
                      if force_profile is not None and posture == "compatible" else None)
        reference = _Reference(task, loop.hold, right_leg_swing(info.joint_names, q_start, swing) if swing else None,
                               compatible, manager)
        duration = duration if duration is not None else (swing or 0.0) + TAIL
        result = loop.run(reference, HOLD + duration)
        run.tripped = result.tripped
        if run.tripped:
            log.warning("%s: safety trip: %s", name, run.tripped)
    finally:
        if stream is not None:
            stream.close()
        backend.close()
    return run


# -- output helpers ------------------------------------------------------------------------------------------
def write_table(path: Path, header: list[str], rows: list[list]) -> str:
    """Write ``path``.csv and ``path``.md; return the Markdown table."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.with_suffix(".csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    md = markdown(header, rows)
    path.with_suffix(".md").write_text(md + "\n")
    return md


def _fmt(v) -> str:
    if isinstance(v, float):
        return "-" if np.isnan(v) else f"{v:.3g}" if abs(v) < 1 else f"{v:.2f}"
    return str(v)


def markdown(header: list[str], rows: list[list]) -> str:
    """A Markdown table; floats with 3 significant digits below 1, 2 decimals above, NaN as '-'."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def pyplot():
    """matplotlib.pyplot on the Agg backend (files only)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def rerun_target(out: Path, rerun: bool, name: str) -> str | None:
    """``save:<out>/<name>.rrd`` with ``rerun``, else None."""
    return f"save:{out / (name + '.rrd')}" if rerun else None


def run_label(k6: float | None) -> str:
    """Column label of a motion run: ``position`` (k6 None) or ``K6=<k6>``."""
    return "position" if k6 is None else f"K6={k6:g}"
