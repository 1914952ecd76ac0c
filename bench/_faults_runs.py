"""The controller-trip and load runs of bench/faults.py (``trip_drop_mrad_max``,
``realtime_torque_runs_completed_under_load_fraction``): ``servotau sim`` + ``servotau control`` on 127.0.0.1, each in
its own process group, killed on exit."""

from __future__ import annotations

import os
import re
import signal
import time
from pathlib import Path

import numpy as np
from _faults_peers import ROOT, Peer, control_process, kill_group, progress, sim_process, spawn

from servotau.hal.log import read_log

SETTLE = 0.5  # [s] the controller's settle phase (control/loop.py SETTLE)


# ---------------------------------------------------------------------------------------------- trip

def _motion_mrad(c: dict, names, t_from: float, t_to: float) -> float:
    q = np.column_stack([c[f"q/{n}"] for n in names])
    t = c["t"]
    i0 = int(np.searchsorted(t, t_from))
    win = q[i0:int(np.searchsorted(t, t_to))]
    return float(np.nanmax(np.abs(win - q[i0]))) * 1e3 if len(win) else float("nan")


def _trip_run(tmp: Path, clock: str, i: int = 0, hal: Path | None = None, trip_at: float = 0.5, window: float = 10.0,
              after_exit: float = 5.0) -> dict:
    tag = f"trip-{clock}-{i}{'' if hal is None else '-fifo'}"
    rlog, clog = tmp / f"{tag}-robot.parquet", tmp / f"{tag}-ctl.parquet"
    with sim_process(tmp, clock=clock, log=rlog, hal=hal) as (_, port):
        obs = Peer("hrp2", f"tcp/127.0.0.1:{port}")
        try:
            ctl = control_process(tmp, port, "--trip-at", str(trip_at), "--hold-timeout", "12", "--log", str(clog),
                                  tag=tag, hal=hal)
            try:
                code = ctl.wait(180)
            finally:
                kill_group(ctl)
            t_exit = obs.newest[1]
            obs.wait(lambda p: p.newest[1] >= t_exit + after_exit, 60.0)
        finally:
            obs.close()
    names = [n for n in read_log(rlog)[0].joint_names]
    _, c = read_log(rlog)
    _, cc = read_log(clog)
    text = (tmp / f"{tag}-{port}.out").read_text()
    said = re.search(r"safety trip \[command_error\].* at t = ([0-9.]+) s", text)
    t_trip = float(said.group(1)) if said else float(cc["t"][0]) + SETTLE + trip_at  # as the controller reports it
    r = {"clock": clock, "sched_fifo": hal is not None, "controller_exit_code": code, "trip_robot_time_s": t_trip,
         "drop_mrad": _motion_mrad(c, names, t_trip, t_trip + window),
         "drift_after_100ms_mrad": _motion_mrad(c, names, t_trip + 0.1, t_trip + window),
         "after_exit_mrad": _motion_mrad(c, names, t_exit, t_exit + after_exit),
         "servo_off_ticks": int((c["hal/state"] == 3.0).sum())}
    progress(f"trip: {r}")
    return r


def bench_trip(tmp: Path, clocks: tuple[str, ...], runs: int, sched: str) -> dict:
    """``runs`` trip runs per clock of ``clocks``: realtime ones with robot and controller under SCHED_FIFO
    (:func:`realtime_hal`, as docs/real_backend.md asks of a realtime loop) if ``sched`` is ``fifo``, with ordinary
    scheduling if ``ordinary``, both if ``both`` (the figure from the SCHED_FIFO runs, the others reported apart);
    lock-step ones as shipped. The figure is the largest drop of those runs."""
    fifo = realtime_hal(tmp, ROOT / "config" / "hal.toml")
    scheds = {"fifo": (fifo,), "ordinary": (None,), "both": (fifo, None)}[sched]
    plan = [(c, hal) for c in clocks for hal in (scheds if c == "realtime" else (None,))]
    results = [_trip_run(tmp, c, i, hal) for c, hal in plan for i in range(runs)]
    main = [r for r in results if r["clock"] == "lockstep" or r["sched_fifo"] == (sched != "ordinary")]
    drops: dict[str, list[float]] = {}
    for r in results:
        key = r["clock"] if r["clock"] == "lockstep" else f"realtime_{'fifo' if r['sched_fifo'] else 'ordinary'}"
        drops.setdefault(key, []).append(r["drop_mrad"])
    return {"trip_drop_mrad_max": max(r["drop_mrad"] for r in main),
            "trip_drop_after_exit_mrad_max": max(r["after_exit_mrad"] for r in results), "trip_drop_mrad": drops,
            "trip_realtime_sched": sched, "trip_runs": results}


# ---------------------------------------------------------------------------------------------- load

def realtime_hal(tmp: Path, base: Path, robot_priority: int = 60, controller_priority: int = 50) -> Path:
    """A copy of ``base`` (a hal.toml) with SCHED_FIFO ``realtime_priority`` for the robot ([hal.server]) and the
    controller ([hal.zenoh]): how docs/real_backend.md says to run a realtime loop on a loaded machine."""
    lines = []
    for line in base.read_text().splitlines():
        lines.append(line)
        if line.startswith("[hal.zenoh]"):
            lines.append(f"realtime_priority = {controller_priority}")
        elif line.startswith("[hal.server]"):
            lines.append(f"realtime_priority = {robot_priority}")
    out = tmp / "hal-realtime.toml"
    out.write_text("\n".join(lines) + "\n")
    return out


def _load_runs(tmp: Path, runs: int, hal: Path | None, tag: str) -> list[dict]:
    results = []
    for i in range(runs):
        with sim_process(tmp, clock="realtime", hal=hal) as (_, port):
            ctl = control_process(tmp, port, "--mode", "torque", "--hold-timeout", "1", tag=f"{tag}-{i}", hal=hal)
            try:
                code = ctl.wait(180)
            finally:
                kill_group(ctl)
        out = (tmp / f"{tag}-{i}-{port}.out").read_text().splitlines()
        first = next((line for line in out if " ticks, " in line and "frames skipped in" in line),
                     out[-1] if out else "")
        trip = next((line for line in out if line.startswith("SAFETY TRIP")), None)
        fifo = [(tmp / f"{w}-{port}.out").read_text().count("SCHED_FIFO priority") > 0
                for w in ("sim", f"{tag}-{i}")]
        results.append({"exit_code": code, "summary": first[:300], "trip": trip and trip[:200],
                        "sched_fifo_robot_controller": fifo, "loadavg_1min": os.getloadavg()[0]})
        progress(f"{tag} run {i}: exit {code}: {first[:200]}")
    return results


def bench_load(tmp: Path, runs: int, hal: Path | None, busy: int = 4, ordinary_runs: int = 0) -> dict:
    """``runs`` realtime torque runs with ``busy`` busy loops, robot and controller under SCHED_FIFO (``hal``:
    the controller's and robot's hal.toml, default :func:`realtime_hal` of config/hal.toml); then
    ``ordinary_runs`` with ordinary scheduling (config/hal.toml as shipped), reported apart."""
    hal = hal or realtime_hal(tmp, ROOT / "config" / "hal.toml")
    loads = [spawn(["sh", "-c", "while :; do :; done"], tmp / f"busy-{i}.out") for i in range(busy)]
    try:
        time.sleep(1.0)
        results = _load_runs(tmp, runs, hal, "load")
        ordinary = _load_runs(tmp, ordinary_runs, None, "load-ordinary")
    finally:
        for p in loads:
            kill_group(p, signal.SIGKILL)
    done = sum(r["exit_code"] == 0 for r in results)
    out = {"realtime_torque_runs_completed_under_load_fraction": done / max(len(results), 1),
           "load_runs": results, "load_busy_processes": busy, "load_hal": str(hal),
           "load_sched_fifo_in_effect": all(all(r["sched_fifo_robot_controller"]) for r in results)}
    if ordinary:
        out["load_ordinary_scheduling_completed_fraction"] = sum(r["exit_code"] == 0 for r in ordinary) / len(ordinary)
        out["load_ordinary_runs"] = ordinary
    return out
