"""Simulator speed: simulated seconds per wall second, in process, 1 kHz, servo and sensors on.

Usage: python bench/sim.py [--json] [--seconds 5]
Target: rtf >= 5 on a 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from servotau.simrobot.sim import SimConfig, SimRobot


def rtf(scenario: str, seconds: float) -> float:
    robot = SimRobot(SimConfig.named(scenario))
    q0 = robot.read().q.copy()
    n = int(seconds / robot.period)
    knee = robot.info.joint_index("RLEG_JOINT3")
    t0 = time.perf_counter()
    for k in range(n):
        q = q0.copy()
        q[knee] += 0.2 * np.sin(2 * np.pi * 0.5 * k * robot.period)
        robot.step(q)
        robot.read()
    return seconds / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--seconds", type=float, default=5.0, help="simulated seconds per scenario [s]")
    args = ap.parse_args()
    out = {f"rtf_{s}": round(rtf(s, args.seconds), 2) for s in ("hanging", "standing")}
    out["target_rtf"] = 5.0
    print(json.dumps(out) if args.json else "\n".join(f"{k}: {v}" for k, v in out.items()))


if __name__ == "__main__":
    main()
