"""Speed of the HAL: lock-step over Zenoh between two processes, round trip, real-time jitter, codec.

Usage:
    python bench/hal.py --json                  # one JSON object (real-time part: 60 s)
    python bench/hal.py --json --duration 5     # shorter real-time part
    python bench/hal.py --robot servotau.simrobot.sim:SimRobot.from_config --scenario sim.toml

The robot process is ``python -m servotau.hal`` (the HAL server) on tcp/127.0.0.1 (a free port),
serving servotau.simrobot.fake's FakeRobot (30 joints) unless ``--robot`` names another factory; the
controller (this process) reads a frame and writes 30 desired angles by name every tick (no ground
truth: a pure controller).

- ``lockstep_rtf``: lock-step, simulated seconds per wall second (target >= 2).
- ``rtt_p50_us`` / ``rtt_p99_us``: lock-step, frame published -> its command received, robot side.
- ``lockstep_cpu_us_per_tick_controller`` / ``_robot``: CPU time of each process (all its threads,
  zenoh's included) per lock-step tick: the HAL's own cost, which a shared machine's load changes
  much less than the wall-clock figures.
- ``realtime_late_fraction``: real-time mode (1 kHz), fraction of ticks starting more than one
  period late, over ``--duration`` seconds.
- ``*_fifo50``: the same figures with both processes under SCHED_FIFO priority 50
  (``realtime_priority``, hal/robot/realtime.py; as a robot's control loop runs), if the user may.
- ``encode_us`` / ``decode_us``: one 30-joint frame (best of 5).
- ``robot_lost_ms_p50`` / ``_max``: from the robot process's SIGKILL to the controller's ``RobotLost`` (the robot's
  liveliness token gone), over ``--lost-runs`` runs; target 100 ms (docs/real_backend.md, "Kill the bridge").
- ``baseline_rtt_p50_us`` / ``_p99_us``: a bare Zenoh Python ping-pong with the same sizes,
  settings and threading (bench/_zenoh_pingpong.py, ``channel``), in the same run;
  ``rtt_*_ratio_to_baseline``: what the HAL adds, as a ratio that a shared machine's load changes
  less than the absolute figures. ``baseline_threads_*``: the same ping-pong through Python
  callback threads (the HAL's pattern before); ``threads_to_channel_*_ratio``: what the channel
  pattern saves. ``baseline_zenoh_default_pools_*``: the channel ping-pong with zenoh's default
  runtime pools (``ZENOH_RUNTIME="()"``) instead of the HAL's layout; ``*_cpu_us_per_rt``: the
  robot process's CPU time per round trip; ``default_pools_to_hal_layout_cpu_ratio``: what the
  layout saves.

Wall-clock figures depend on the machine's load: ``cpu_count`` and ``loadavg_1min`` are reported.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import timeit
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from servotau.apps.processes import free_port, stop_process, wait_ready
from servotau.hal import RobotLost, ZenohBackend
from servotau.hal.wire.protocol import decode_frame, encode_frame
from servotau.simrobot.fake import FakeRobot

FAKE_ROBOT = "servotau.simrobot.fake:FakeRobot"


@contextmanager
def _robot_process(robot: str, scenario: str | None, clock: str, priority: int = 0):
    """The robot process (the HAL server) on a free loopback port, ready: ``(process, endpoint)``."""
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        ready = Path(tmp) / "ready"
        args = [sys.executable, "-m", "servotau.hal", "--robot", robot, "--listen", f"tcp/127.0.0.1:{port}",
                "--clock", clock, "--ready-file", str(ready), "--realtime-priority", str(priority)]
        if scenario:
            args += ["--scenario", scenario]
        p = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            wait_ready(p, ready, 30.0, f"robot server ({' '.join(args)})")
            yield p, f"tcp/127.0.0.1:{port}"
        finally:
            stop_process(p)


@contextmanager
def _server(robot: str, scenario: str | None, clock: str, priority: int = 0):
    with _robot_process(robot, scenario, clock, priority) as (_, endpoint):
        with ZenohBackend(_robot_name(robot, scenario), connect=[endpoint], truth=False,
                          realtime_priority=priority) as backend:
            yield backend


def _robot_name(robot: str, scenario: str | None) -> str:
    from servotau.hal import import_object

    if robot == FAKE_ROBOT:
        return "fake"
    factory = import_object(robot)
    return (factory(scenario) if scenario else factory()).info.name


def _control(backend: ZenohBackend, seconds: float | None = None, ticks: int | None = None) -> tuple[int, float]:
    """Read/write loop: hold the first posture plus a small sinusoid on one joint; (ticks, wall s)."""
    names = backend.info.joint_names
    f0 = backend.read()
    q0 = dict(zip(names, f0.q.tolist(), strict=True))
    f, k, t0 = f0, 0, time.perf_counter()
    while (ticks is None or k < ticks) and (seconds is None or time.perf_counter() - t0 < seconds):
        q0[names[0]] = float(f0.q[0] + 0.01 * np.sin(2 * np.pi * f.time))
        backend.write(q0)
        f = backend.read()
        k += 1
    return k, time.perf_counter() - t0


def bench_lockstep(robot: str, scenario: str | None, ticks: int, priority: int = 0) -> dict:
    with _server(robot, scenario, "lockstep", priority) as b:
        _control(b, ticks=200)  # warm up
        cpu0, robot_cpu0 = time.process_time(), b.status()["process_cpu_s"]
        n, wall = _control(b, ticks=ticks)
        cpu, st = time.process_time() - cpu0, b.status()
    sfx = f"_fifo{priority}" if priority else ""
    return {f"lockstep_rtf{sfx}": n * b.info.period / wall, f"lockstep_tick_us{sfx}": wall / n * 1e6,
            f"rtt_p50_us{sfx}": st["rtt_p50_us"], f"rtt_p99_us{sfx}": st["rtt_p99_us"],
            f"lockstep_cpu_us_per_tick_controller{sfx}": cpu / n * 1e6,
            f"lockstep_cpu_us_per_tick_robot{sfx}": (st["process_cpu_s"] - robot_cpu0) / n * 1e6}


def bench_realtime(robot: str, scenario: str | None, duration: float, priority: int = 0) -> dict:
    with _server(robot, scenario, "realtime", priority) as b:
        st0 = b.status()
        _control(b, seconds=duration)
        st = b.status()
    ticks = st["ticks"] - st0["ticks"]
    late = st["late_ticks"] - st0["late_ticks"]
    sfx = f"_fifo{priority}" if priority else ""
    return {f"realtime_late_fraction{sfx}": late / max(ticks, 1), f"realtime_ticks{sfx}": ticks,
            f"realtime_holds{sfx}": st["holds"]}


def bench_robot_lost(runs: int) -> dict:
    """From the robot process's SIGKILL to :class:`RobotLost` in the controller's read/write loop (its liveliness
    token gone; the frame timeout, 5 s here, never fires first), wall time over ``runs`` runs."""
    ms = []
    for _ in range(runs):
        with _robot_process(FAKE_ROBOT, None, "lockstep") as (p, endpoint):
            with ZenohBackend("fake", connect=[endpoint], truth=False, frame_timeout=5.0) as b:
                _control(b, ticks=300)
                t_kill = time.monotonic()
                os.kill(p.pid, signal.SIGKILL)
                try:
                    _control(b, seconds=10.0)
                except RobotLost:
                    ms.append((time.monotonic() - t_kill) * 1e3)
                else:
                    raise SystemExit("bench_robot_lost: the controller ran 10 s after the robot's SIGKILL")
    return {"robot_lost_ms_p50": float(np.median(ms)), "robot_lost_ms_max": max(ms), "robot_lost_target_ms": 100.0,
            "robot_lost_met": max(ms) <= 100.0, "robot_lost_runs": runs}


def bench_baseline(ticks: int, pattern: str = "channel", zenoh_runtime: str | None = None,
                   prefix: str | None = None) -> dict:
    """Bare Zenoh ping-pong (bench/_zenoh_pingpong.py), the floor under ``rtt_*``, in this run;
    ``zenoh_runtime``: the ZENOH_RUNTIME of both processes (None: the HAL's layout)."""
    port, script = free_port(), str(Path(__file__).with_name("_zenoh_pingpong.py"))
    env = dict(os.environ, **({"ZENOH_RUNTIME": zenoh_runtime} if zenoh_runtime is not None else {}))
    robot = subprocess.Popen([sys.executable, script, "robot", str(port), str(ticks), pattern], stdout=subprocess.PIPE,
                             text=True, env=env)
    ctl = subprocess.Popen([sys.executable, script, "controller", str(port), str(ticks), pattern], env=env)
    try:
        out, _ = robot.communicate(timeout=180)
        ctl.wait(30)
    finally:
        stop_process(robot)
        stop_process(ctl)
    r = json.loads(out)
    prefix = prefix or ("baseline" if pattern == "channel" else f"baseline_{pattern}")
    return {f"{prefix}_rtt_p50_us": r["rtt_p50_us"], f"{prefix}_rtt_p99_us": r["rtt_p99_us"],
            f"{prefix}_cpu_us_per_rt": r["cpu_us_per_rt"]}


def bench_codec() -> dict:
    frame = FakeRobot().read()
    buf = encode_frame(frame)
    n = 20_000
    enc = min(timeit.repeat(lambda: encode_frame(frame), number=n, repeat=5)) / n
    dec = min(timeit.repeat(lambda: decode_frame(buf, 30), number=n, repeat=5)) / n
    return {"encode_us": enc * 1e6, "decode_us": dec * 1e6, "frame_bytes": len(buf)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--duration", type=float, default=60.0, help="real-time part [s] (default 60)")
    ap.add_argument("--ticks", type=int, default=5000, help="lock-step ticks (default 5000)")
    ap.add_argument("--robot", default=FAKE_ROBOT, help="robot factory 'module:callable'")
    ap.add_argument("--scenario", help="config path passed to the robot factory")
    ap.add_argument("--fifo", type=int, default=50,
                    help="also run both parts with both processes under SCHED_FIFO at this priority (0: skip; "
                         "without the permission they warn and run with ordinary scheduling)")
    ap.add_argument("--lost-runs", type=int, default=5, help="robot SIGKILL runs (default 5)")
    args = ap.parse_args()
    out = {**bench_codec(), **bench_robot_lost(args.lost_runs),
           **bench_baseline(args.ticks), **bench_baseline(args.ticks, "threads"),
           **bench_baseline(args.ticks, zenoh_runtime="()", prefix="baseline_zenoh_default_pools"),
           **bench_lockstep(args.robot, args.scenario, args.ticks),
           **bench_realtime(args.robot, args.scenario, args.duration),
           **(bench_lockstep(args.robot, args.scenario, args.ticks, args.fifo) if args.fifo else {}),
           **(bench_realtime(args.robot, args.scenario, args.duration, args.fifo) if args.fifo else {}),
           "robot": args.robot, "cpu_count": os.cpu_count(), "loadavg_1min": os.getloadavg()[0]}
    out["rtt_p50_ratio_to_baseline"] = out["rtt_p50_us"] / out["baseline_rtt_p50_us"]
    out["rtt_p99_ratio_to_baseline"] = out["rtt_p99_us"] / out["baseline_rtt_p99_us"]
    for q in ("p50", "p99"):  # > 1: the HAL's channel pattern saves that much over a callback thread
        out[f"threads_to_channel_{q}_ratio"] = out[f"baseline_threads_rtt_{q}_us"] / out[f"baseline_rtt_{q}_us"]
    # > 1: the HAL's zenoh runtime layout (hal/wire/session.py ZENOH_RUNTIME) saves that much robot-side CPU
    out["default_pools_to_hal_layout_cpu_ratio"] = (out["baseline_zenoh_default_pools_cpu_us_per_rt"]
                                                    / out["baseline_cpu_us_per_rt"])
    out = {k: round(v, 4) if isinstance(v, float) else v for k, v in out.items()}
    print(json.dumps(out) if args.json else json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
