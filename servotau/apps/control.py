"""``servotau control``: the controller process.

Connects to the robot through the HAL (backend chosen in config/hal.toml or by ``--backend``),
estimates joint torques, runs the right-leg swing in position or torque mode, records a Parquet log
and streams to Rerun. On a safety trip the robot is held in position and the process exits with
code 3; if the robot disappears it exits with code 4.

The loop is :class:`servotau.control.loop.ControlLoop`; this module adds its hooks: the tracking error
(:class:`TrackingError`), the Parquet log (:class:`LogHook`) and the Rerun stream (:class:`RerunHook`).
"""

from __future__ import annotations

import logging
import sys
from dataclasses import dataclass

import numpy as np

from servotau.apps.viewer import RerunStream, open_recording
from servotau.control.loop import ControlLoop, LoopHook, Tick
from servotau.control.trajectory import right_leg_swing
from servotau.errors import HalError

log = logging.getLogger(__name__)

TAIL = 0.5  # [s] after the swing, still run and evaluated


@dataclass(frozen=True)
class SessionResult:
    ticks: int
    sim_seconds: float
    wall_seconds: float
    max_error: dict  # joint -> max |q_des - q| [rad] during the motion
    tripped: str | None


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


class RerunHook(LoopHook):
    """Every tick to a :class:`~servotau.apps.viewer.RerunStream`: joint signals, command components, IMU, F/T, the
    ground-truth torque and the 3D robot (at the ground-truth base pose when there is one)."""

    wants_truth = True

    def __init__(self, stream: RerunStream, ft_sensor_names):
        self.stream = stream
        self.ft_sensor_names = tuple(ft_sensor_names)

    def on_tick(self, tick: Tick) -> None:
        frame, terms, truth = tick.frame, tick.terms, tick.truth
        signals = {"q": frame.q, "q_des": terms.q_des, "q_ref": tick.reference.q, "dq_err": terms.q_des - frame.q,
                   "tau_est": tick.estimate.tau, "ff_friction": terms.ff_friction, "ff_extra": terms.ff_extra,
                   "ff_torque": terms.ff_torque,
                   "fb_position": terms.fb_position, "fb_velocity": terms.fb_velocity,
                   "fb_acceleration": terms.fb_acceleration, "fb_force": terms.fb_force,
                   "imu/gyro": frame.imu_angular_velocity, "imu/acc": frame.imu_linear_acceleration}
        for s, name in enumerate(self.ft_sensor_names):
            signals[f"ft/{name}/force"] = frame.wrenches[s, :3]
            signals[f"ft/{name}/torque"] = frame.wrenches[s, 3:]
        if truth is not None:
            signals["tau_true"] = truth.tau
        self.stream.add(frame.time, **signals)
        base = (truth.base_position, truth.base_quat_wxyz) if truth is not None else (None, None)
        self.stream.robot(frame.time, frame.q, *base)


class _Progress(LoopHook):
    def __init__(self, progress, mode: str, duration: float):
        self.progress, self.mode, self.duration = progress, mode, duration

    def settled(self, tick: Tick) -> None:
        self.progress(f"swinging the right leg in {self.mode} mode for {self.duration:.1f} s")


# -- the session ----------------------------------------------------------------------------------------
def register(sub) -> None:
    p = sub.add_parser("control", help="run the controller on a HAL backend (sim or real robot)")
    p.add_argument("--hal", default="hal.toml", help="HAL config: [hal] backend = zenoh | inprocess | replay")
    p.add_argument("--backend", choices=("zenoh", "inprocess", "replay"), help="override the config's backend")
    p.add_argument("--port", type=int, help="zenoh: the robot's port on 127.0.0.1 (overrides the config)")
    p.add_argument("--mode", choices=("position", "torque"), default="position")
    p.add_argument("--duration", type=float, default=3.0, help="swing duration [s]")
    p.add_argument("--log", default=None, help="Parquet log path")
    p.add_argument("--rerun", default="off", help="save:FILE | connect:ADDR | spawn | off")
    p.set_defaults(func=main)


def run_session(backend, *, mode: str, duration: float, stream: RerunStream | None = None, writer=None,
                progress=print) -> SessionResult:
    """Settle, then swing the right leg in ``mode`` (:class:`~servotau.control.loop.ControlLoop`).

    Args:
        backend: The HAL backend.
        mode: ``position`` or ``torque``.
        duration: [s] of the swing (then :data:`TAIL` s holding its end).
        stream: Rerun stream, or None.
        writer: :class:`~servotau.hal.log.LogWriter`, or None.
        progress: Called with a line of text at the swing's start and on a safety trip.
    """
    info = backend.info
    error = TrackingError(info.nq)
    hooks = [error, _Progress(progress, mode, duration)]
    if writer is not None:
        hooks.append(LogHook(writer))
    if stream is not None:
        hooks.append(RerunHook(stream, info.ft_sensor_names))
    loop = ControlLoop(backend, mode=mode, hooks=hooks)
    traj = right_leg_swing(info.joint_names, loop.start().q, duration)
    result = loop.run(lambda tick: traj.sample(tick.t), duration + TAIL)
    if result.tripped:
        progress(f"SAFETY TRIP: {result.tripped}: holding position")
    return SessionResult(
        ticks=result.ticks, sim_seconds=result.sim_seconds, wall_seconds=result.wall_seconds,
        max_error={j: float(e) for j, e in zip(info.joint_names, error.max, strict=True)},
        tripped=result.tripped,
    )


def main(args) -> int:
    from servotau.hal.log import LogWriter
    from servotau.hal.registry import open_backend, overrides_from_args

    backend = open_backend(args.hal, **overrides_from_args(args))
    rec = open_recording(args.rerun)
    stream = RerunStream(rec, backend.info.joint_names, backend.info.model_path) if rec is not None else None
    writer = LogWriter(args.log, backend.info, metadata={"mode": args.mode}) if args.log else None
    try:
        result = run_session(backend, mode=args.mode, duration=args.duration, stream=stream, writer=writer)
    except HalError as exc:
        print(f"servotau control: robot lost: {exc}", file=sys.stderr)
        return 4
    finally:
        if writer is not None:
            writer.close()
        if stream is not None:
            stream.close()
        backend.close()
    legs = [j for j in backend.info.joint_names if j.startswith("RLEG")]
    print(f"{result.ticks} ticks, {result.sim_seconds:.2f} s robot time in {result.wall_seconds:.2f} s wall "
          f"({result.sim_seconds / result.wall_seconds:.2f}x real time)")
    print("max |q_ref - q| [mrad]: " + ", ".join(f"{j} {1e3 * result.max_error[j]:.1f}" for j in legs))
    if result.tripped:
        print(f"safety trip: {result.tripped}", file=sys.stderr)
        return 3
    return 0
