"""Time one control tick in process: estimation (TorqueEstimator.update) + control (ControlManager.tick).

Frames are recorded first from the simulated HRP-2 (30 joints, hanging, right leg in torque mode), then replayed
through a fresh estimator and controller in a tight loop, as the control process sees them (the simulator runs in
another process in the real setup). Both passes run the control loop (control/loop.py), which times its estimate
and its control tick. Prints JSON with the median and 99th percentile per tick [us], also split into estimation and
control. Also the position integral's update alone (control/position_integral.py: 30 joints, the 6 of the right
leg integrating), without and with a 5-row force-task Jacobian, and its share of the control tick.
"""

import argparse
import json
import time

import numpy as np

from servotau.control.estimator_variant import ESTIMATOR_VARIANT
from servotau.control.loop import ControlLoop, LoopHook
from servotau.control.position_integral import PositionIntegral
from servotau.hal.backends.inprocess import InProcessBackend
from servotau.simrobot.sim import SimConfig, SimRobot

TORQUE_AT = 200  # [ticks] the settle phase: switch to torque mode once the estimator's windows are full


class _Frames(LoopHook):
    """Keeps every frame (the frames are new objects each tick)."""

    def __init__(self):
        self.frames = []

    def on_tick(self, tick) -> None:
        self.frames.append(tick.frame)


class _Times(LoopHook):
    """Estimation and control times [ns] of the ticks after the switch to torque mode."""

    def __init__(self):
        self.estimation, self.control = [], []

    def on_tick(self, tick) -> None:
        if tick.k > TORQUE_AT:
            self.estimation.append(tick.estimation_ns)
            self.control.append(tick.control_ns)


class _Replay:
    """The recorded frames as a backend: read() returns the next one (the last again at the end), write() drops."""

    def __init__(self, info, frames):
        self.info, self._frames, self._k = info, frames, 0

    def read(self):
        frame = self._frames[min(self._k, len(self._frames) - 1)]
        self._k += 1
        return frame

    def write(self, q_des) -> None:
        pass

    def ground_truth(self):
        return None


def record(ticks: int):
    """Frames of a closed-loop run (position, then torque mode) and the robot's info."""
    backend = InProcessBackend(SimRobot(SimConfig.named("hanging")))
    kept = _Frames()
    loop = ControlLoop(backend, mode="torque", settle=TORQUE_AT * backend.info.period, hooks=[kept])
    loop.run(None, (ticks - TORQUE_AT) * backend.info.period)
    backend.close()
    return backend.info, kept.frames


def replay(info, frames) -> tuple[np.ndarray, np.ndarray, str]:
    """Per-tick estimation and control times [us] after the switch to torque mode; the final mode."""
    times = _Times()
    loop = ControlLoop(_Replay(info, frames), mode="torque", settle=TORQUE_AT * info.period, hooks=[times])
    loop.run(None, (len(frames) - TORQUE_AT) * info.period)
    return np.array(times.estimation) * 1e-3, np.array(times.control) * 1e-3, loop.manager.mode.value


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
    info, frames = record(args.ticks)
    est_us, ctl_us, modes = [], [], set()
    for _ in range(args.runs):
        e, c, mode = replay(info, frames)
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
        "estimator_variant": ESTIMATOR_VARIANT,
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
