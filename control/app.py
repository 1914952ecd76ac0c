"""``servotau control``: the controller process.

Connects to the robot through the HAL (backend chosen in config/hal.toml or by ``--backend``),
estimates joint torques, runs the right-leg swing in position or torque mode, records a Parquet log
and streams to Rerun. On a safety trip the robot is held in position and the process exits with
code 3; if the robot disappears it exits with code 4.
"""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import dataclass

import numpy as np

from servotau.apps.viewer import RerunStream, open_recording
from servotau.errors import HalError

from .trajectory import TrajectoryPoint, right_leg_swing

log = logging.getLogger(__name__)

SETTLE = 0.5  # [s] held in position mode first: filters fill, F/T offsets are calibrated (feet free)


@dataclass(frozen=True)
class SessionResult:
    ticks: int
    sim_seconds: float
    wall_seconds: float
    max_error: dict  # joint -> max |q_des - q| [rad] during the motion
    tripped: str | None


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
    """Settle, then swing the right leg in ``mode``; one HAL read/write per tick."""
    from servotau.control import ControlManager
    from servotau.estimation import EstimatorConfig, TorqueEstimator, calibrate_ft_offsets

    info = backend.info
    est_cfg = EstimatorConfig.from_toml(variant="low_delay")
    estimator = TorqueEstimator(info, est_cfg)
    manager = ControlManager.from_toml(info)
    frame = backend.read()
    q_start = frame.q.copy()
    traj = right_leg_swing(info.joint_names, q_start, duration)
    hold = TrajectoryPoint(q_start, np.zeros(info.nq), np.zeros(info.nq))
    settle_ticks = int(SETTLE / info.period)
    total = settle_ticks + int((duration + 0.5) / info.period)
    settle_frames = []
    max_err = np.zeros(info.nq)
    t_wall = time.perf_counter()
    k = 0
    for k in range(total):
        estimate = estimator.update(frame)
        if k < settle_ticks:
            settle_frames.append(frame)
            ref = hold
        else:
            if k == settle_ticks:
                estimator.set_ft_offsets(calibrate_ft_offsets(settle_frames, info, est_cfg))
                if mode == "torque":
                    manager.request_mode("torque")
                progress(f"swinging the right leg in {mode} mode for {duration:.1f} s")
            ref = traj.sample((k - settle_ticks) * info.period)
        terms = manager.tick(frame, estimate if estimate.valid else None, ref)
        backend.write(dict(zip(info.joint_names, terms.q_des, strict=True)))
        if k >= settle_ticks:
            np.maximum(max_err, np.abs(ref.q - frame.q), out=max_err)
        truth = backend.ground_truth()
        if writer is not None:
            writer(frame, terms.q_des, estimate, truth)
        if stream is not None:
            signals = {"q": frame.q, "q_des": terms.q_des, "q_ref": ref.q, "dq_err": terms.q_des - frame.q,
                       "tau_est": estimate.tau, "ff_friction": terms.ff_friction, "ff_extra": terms.ff_extra,
                       "ff_torque": terms.ff_torque,
                       "fb_position": terms.fb_position, "fb_velocity": terms.fb_velocity,
                       "fb_acceleration": terms.fb_acceleration, "fb_force": terms.fb_force,
                       "imu/gyro": frame.imu_angular_velocity, "imu/acc": frame.imu_linear_acceleration}
            for s, name in enumerate(info.ft_sensor_names):
                signals[f"ft/{name}/force"] = frame.wrenches[s, :3]
                signals[f"ft/{name}/torque"] = frame.wrenches[s, 3:]
            if truth is not None:
                signals["tau_true"] = truth.tau
            stream.add(frame.time, **signals)
            base = (truth.base_position, truth.base_quat_wxyz) if truth is not None else (None, None)
            stream.robot(frame.time, frame.q, *base)
        if manager.tripped:
            progress(f"SAFETY TRIP: {manager.report.message}: holding position")
            break
        frame = backend.read()
    return SessionResult(
        ticks=k + 1, sim_seconds=(k + 1) * info.period, wall_seconds=time.perf_counter() - t_wall,
        max_error={j: float(e) for j, e in zip(info.joint_names, max_err, strict=True)},
        tripped=manager.report.message if manager.tripped else None,
    )


def main(args) -> int:
    from servotau.hal.log import LogWriter
    from servotau.hal.registry import open_backend, overrides_from_args

    backend = open_backend(args.hal, **overrides_from_args(args))
    rec = open_recording(args.rerun)
    stream = RerunStream(rec, backend.info.joint_names, backend.info.model_path) if rec is not None else None
    writer = LogWriter(args.log, backend.info, metadata={"mode": args.mode}) if args.log else None

    def record(frame, q_des, estimate, truth):
        writer.append(frame, q_des, truth, {"est/tau": estimate.tau, "est/dq": estimate.dq})

    try:
        result = run_session(backend, mode=args.mode, duration=args.duration, stream=stream,
                             writer=record if writer else None)
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
