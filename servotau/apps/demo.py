"""servotau demo: the robot process and the controller process, as a user would start them.

Starts servotau sim (lock-step, loopback, a free port), then servotau control (torque mode,
right-leg swing) against it over Zenoh, records demo.rrd (Rerun) and log.parquet, stops the
robot process and prints a summary. Exits by itself.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

from servotau.apps.config_args import CONTROL, ESTIMATION, HAL, SIM, add_config_args, config_files, forward
from servotau.apps.processes import free_port, stop_process, wait_ready

HOLD_TIMEOUT = 2.0  # [s] robot time the controller holds after a safety trip before it releases (exit code 3)


def register(sub) -> None:
    p = sub.add_parser("demo", help="sim robot process + controller process + Rerun recording",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="runs/demo", help="output folder")
    p.add_argument("--mode", choices=("position", "torque"), default="torque")
    p.add_argument("--duration", type=float, default=3.0, help="swing duration [s]")
    p.add_argument("--port", type=int, help="loopback port of the robot (default: a free one)")
    add_config_args(p, SIM, HAL, CONTROL, ESTIMATION)  # passed on to servotau sim and servotau control
    p.set_defaults(func=main)


def main(args) -> int:
    config_files(args, SIM, HAL, CONTROL, ESTIMATION)  # a bad folder or file flag fails here, before anything starts
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    port = args.port or free_port()
    ready = out / "sim.ready"
    ready.unlink(missing_ok=True)
    cli = [sys.executable, "-m", "servotau.cli"]
    print(f"[demo] starting the robot process: servotau sim --port {port}", flush=True)
    sim = subprocess.Popen([*cli, "sim", *forward(args, SIM, HAL), "--port", str(port), "--ready-file", str(ready)])
    try:
        wait_ready(sim, ready, 60.0)
        print("[demo] starting the controller process", flush=True)
        rrd, log = out / "demo.rrd", out / "log.parquet"
        ctl = subprocess.run([*cli, "control", *forward(args, HAL, CONTROL, ESTIMATION), "--port", str(port),
                              "--mode", args.mode, "--duration", str(args.duration), "--rerun", f"save:{rrd}",
                              "--log", str(log), "--hold-timeout", str(HOLD_TIMEOUT)])
    finally:
        stop_process(sim, timeout=20.0)
        ready.unlink(missing_ok=True)
    if ctl.returncode != 0:
        print(f"[demo] the controller exited with code {ctl.returncode}", file=sys.stderr)
        return ctl.returncode
    mb, seconds = os.path.getsize(rrd) / 1e6, _robot_seconds(log)
    print(f"[demo] done: {rrd} ({mb:.2f} MB, {mb / seconds:.2f} MB per robot second over {seconds:.2f} s; open with "
          f"{Path(sys.executable).parent / 'rerun'} {rrd}), {log} ({os.path.getsize(log) / 1e6:.1f} MB)")
    return 0


def _robot_seconds(log: Path) -> float:
    """[s] robot time the log covers: its first to its last tick, plus one period."""
    import numpy as np
    import pyarrow.parquet as pq

    t = pq.read_table(log, columns=["t"]).column("t").to_numpy()
    return float(t[-1] - t[0] + np.median(np.diff(t))) if len(t) > 1 else 0.0
