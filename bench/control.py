"""Time one control tick in process: estimation (TorqueEstimator.update) + control (ControlManager.tick).

Frames are recorded first from the simulated HRP-2 (30 joints, hanging, right leg in torque mode), then replayed
through a fresh estimator and controller in a tight loop, as the control process sees them (the simulator runs in
another process in the real setup). Prints JSON with the median and 99th percentile per tick [us], also split into
estimation and control. Also the position integral's update alone (control/position_integral.py: 30 joints, the 6 of
the right leg integrating), without and with a 5-row force-task Jacobian, and its share of the control tick.
"""

import argparse
import json
import time

import numpy as np

from servotau.control import ControlManager
from servotau.control.position_integral import PositionIntegral
from servotau.control.trajectory import TrajectoryPoint
from servotau.estimation import EstimatorConfig, TorqueEstimator
from servotau.simrobot.sim import SimConfig, SimRobot

VARIANT = "low_delay"  # the estimator variant the torque controller is stable with in simulation
TORQUE_AT = 200  # [ticks] switch to torque mode once the estimator's windows are full


def record(ticks: int):
    """Frames of a closed-loop run (position, then torque mode) and the robot's info."""
    robot = SimRobot(SimConfig.named("hanging"))
    est = TorqueEstimator(robot.info, EstimatorConfig.from_toml(variant=VARIANT))
    mgr = ControlManager.from_toml(robot.info)
    frame = robot.read()
    ref = TrajectoryPoint(frame.q.copy(), np.zeros(30), np.zeros(30))
    frames = []
    for k in range(ticks):
        frames.append(frame)
        e = est.update(frame)
        if k == TORQUE_AT:
            mgr.request_mode("torque")
        robot.step(mgr.tick(frame, e if e.valid else None, ref).q_des)
        frame = robot.read()
    return robot.info, frames, ref


def replay(info, frames, ref) -> tuple[np.ndarray, np.ndarray, str]:
    """Per-tick estimation and control times [us] after the switch to torque mode; the final mode."""
    est = TorqueEstimator(info, EstimatorConfig.from_toml(variant=VARIANT))
    mgr = ControlManager.from_toml(info)
    t_est, t_ctl = [], []
    clock = time.perf_counter_ns
    for k, frame in enumerate(frames):
        if k == TORQUE_AT:
            mgr.request_mode("torque")
        t0 = clock()
        e = est.update(frame)
        t1 = clock()
        mgr.tick(frame, e if e.valid else None, ref)
        t2 = clock()
        if k > TORQUE_AT:
            t_est.append(t1 - t0)
            t_ctl.append(t2 - t1)
    return np.array(t_est) * 1e-3, np.array(t_ctl) * 1e-3, mgr.mode.value


def position_integral_us(n: int = 30, k: int = 5, reps: int = 5000) -> tuple[np.ndarray, np.ndarray]:
    """Per-call times [us] of PositionIntegral.update without and with a (k, n) task Jacobian."""
    rng = np.random.default_rng(0)
    rate = np.zeros(n)
    rate[:6] = 2.0
    pi = PositionIntegral(np.full(n, 1e3), rate, np.full(n, 1e-3), 1e-3, 1e-3)
    e_q, dq_d, jac = rng.normal(0.0, 1e-3, n), np.zeros(n), rng.normal(size=(k, n))
    clock = time.perf_counter_ns
    out = []
    for task in (None, jac):
        t = np.empty(reps)
        for r in range(reps):
            t0 = clock()
            pi.update(e_q, dq_d, task)
            t[r] = clock() - t0
        out.append(t * 1e-3)
    return out[0], out[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--json", action="store_true", help="print JSON (the only output format)")
    parser.add_argument("--ticks", type=int, default=3000, help="recorded ticks per replay")
    parser.add_argument("--runs", type=int, default=3, help="replays")
    args = parser.parse_args()
    info, frames, ref = record(args.ticks)
    est_us, ctl_us, modes = [], [], set()
    for _ in range(args.runs):
        e, c, mode = replay(info, frames, ref)
        est_us.append(e)
        ctl_us.append(c)
        modes.add(mode)
    est_us, ctl_us = np.concatenate(est_us), np.concatenate(ctl_us)
    tick_us = est_us + ctl_us
    pint_us, pint_task_us = position_integral_us()

    def pct(x, p):
        return round(float(np.percentile(x, p)), 1)

    print(json.dumps({
        "n_joints": info.nq,
        "estimator_variant": VARIANT,
        "mode": "/".join(sorted(modes)),
        "n_ticks": int(tick_us.size),
        "tick_us_p50": pct(tick_us, 50),
        "tick_us_p99": pct(tick_us, 99),
        "estimation_us_p50": pct(est_us, 50),
        "estimation_us_p99": pct(est_us, 99),
        "control_us_p50": pct(ctl_us, 50),
        "control_us_p99": pct(ctl_us, 99),
        "position_integral_us_p50": pct(pint_us, 50),
        "position_integral_task_us_p50": pct(pint_task_us, 50),
        "position_integral_task_to_control_p50_ratio": round(pct(pint_task_us, 50) / pct(ctl_us, 50), 3),
        "targets_us": {"p50": 200, "p99": 500},
    }))


if __name__ == "__main__":
    main()
