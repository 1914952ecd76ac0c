"""servotau demo: the robot process and the controller process, started and stopped as a user would."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from servotau.hal.log import LogReader


def test_demo_runs_sim_and_controller_processes_and_exits(tmp_path):
    """`servotau demo`: robot process + controller process over Zenoh on loopback; log and .rrd written."""
    out = tmp_path / "demo"
    proc = subprocess.run([sys.executable, "-m", "servotau.cli", "demo", "--out", str(out), "--duration", "2.0",
                           "--mode", "position"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "[demo] done" in proc.stdout and "MB per robot second" in proc.stdout
    rrd = out / "demo.rrd"
    rerun_cli = str(Path(sys.executable).with_name("rerun"))  # installed with rerun-sdk
    assert subprocess.run([rerun_cli, "rrd", "verify", str(rrd)], capture_output=True).returncode == 0
    stats = subprocess.run([rerun_cli, "rrd", "stats", str(rrd)], capture_output=True, text=True).stdout
    for entity in ("/signals", "tracking:RLEG_JOINT3", "torque:RLEG_JOINT3", "command:RLEG_JOINT3", "imu:gyro",
                   "ft:right_ankle_force", "/robot/BODY/RLEG_LINK0/RLEG_LINK1/RLEG_LINK2/RLEG_LINK3"):
        assert f"{entity}:" in stats, entity
    log = LogReader(out / "log.parquet")
    assert len(log) >= 2900  # 0.5 s settle + 2.5 s swing at 1 kHz
    seq = log.columns["seq"]
    assert np.all(np.diff(seq) == 1)  # lock-step: no lost tick
    assert log.info.joint_names[3] == "RLEG_JOINT3"
    assert not any(p.endswith("sim.ready") for p in os.listdir(out))
