"""Tests of the processes a user starts: servotau control (in process), servotau demo (two processes)."""

import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from servotau.apps.control import run_session
from servotau.hal.factory import open_backend
from servotau.hal.log import LogReader
from servotau.viewer import RerunStream, open_recording

LEG = [f"RLEG_JOINT{i}" for i in range(6)]


def session(mode, duration=3.0, stream=None):
    backend = open_backend("hal.toml", backend="inprocess")
    try:
        return run_session(backend, mode=mode, duration=duration, stream=stream, progress=lambda _: None)
    finally:
        backend.close()


def test_torque_mode_tracks_the_swing_better_than_the_position_servo():
    """The hanging right-leg swing: torque control (K6 = 1) beats the native position servo on the leg."""
    pos, tor = session("position"), session("torque")
    assert pos.tripped is None and tor.tripped is None
    worst_pos = max(pos.max_error[j] for j in LEG)
    worst_tor = max(tor.max_error[j] for j in LEG)
    assert worst_tor < 0.5 * worst_pos, (worst_tor, worst_pos)
    for j in ("RLEG_JOINT2", "RLEG_JOINT3", "RLEG_JOINT4"):  # the joints the swing moves most
        assert tor.max_error[j] < pos.max_error[j]


def test_rerun_stream_saves_a_recording_with_gaps_in_signals(tmp_path):
    """Streaming to a .rrd file works, including a signal that is missing on some ticks, without warnings."""
    path = tmp_path / "s.rrd"
    from servotau.simrobot.model import JOINT_NAMES as joints
    from servotau.simrobot.model import MODEL_PATH

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        stream = RerunStream(open_recording(f"save:{path}"), joints, str(MODEL_PATH), flush_every=50)
        for k in range(120):
            extra = {"tau_true": np.ones(30)} if k % 3 else {}
            stream.add(k * 1e-3, q=np.full(30, k * 1e-3), **{"imu/gyro": np.zeros(3)}, **extra)
        stream.close()
    assert path.stat().st_size > 1000


def test_bad_rerun_target_or_joint_names_are_clear_errors(tmp_path):
    """An unknown --rerun target names the expected forms; joints missing from the model are named."""
    from servotau.errors import ConfigError
    from servotau.simrobot.model import MODEL_PATH

    with pytest.raises(ConfigError, match="save:FILE, connect:ADDR, spawn"):
        open_recording("view:here")
    with pytest.raises(ConfigError, match=r"joints \['J9'\] are not in the model"):
        RerunStream(open_recording(f"save:{tmp_path / 'x.rrd'}"), ("J9",), str(MODEL_PATH))


def test_demo_runs_sim_and_controller_processes_and_exits(tmp_path):
    """`servotau demo`: robot process + controller process over Zenoh on loopback; log and .rrd written."""
    out = tmp_path / "demo"
    proc = subprocess.run([sys.executable, "-m", "servotau.cli", "demo", "--out", str(out), "--duration", "2.0",
                           "--mode", "position"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "[demo] done" in proc.stdout
    rrd = out / "demo.rrd"
    rerun_cli = str(Path(sys.executable).with_name("rerun"))  # installed with rerun-sdk
    assert subprocess.run([rerun_cli, "rrd", "verify", str(rrd)], capture_output=True).returncode == 0
    stats = subprocess.run([rerun_cli, "rrd", "stats", str(rrd)], capture_output=True, text=True).stdout
    for entity in ("/joints/RLEG_JOINT3/q", "/joints/RLEG_JOINT3/q_des", "/joints/RLEG_JOINT3/tau_est",
                   "/joints/RLEG_JOINT3/tau_true", "/imu/gyro/0", "/ft/right_ankle/force/2", "/robot/boxes"):
        assert f"{entity}:" in stats, entity
    log = LogReader(out / "log.parquet")
    assert len(log) >= 2900  # 0.5 s settle + 2.5 s swing at 1 kHz
    seq = log.columns["seq"]
    assert np.all(np.diff(seq) == 1)  # lock-step: no lost tick
    assert log.info.joint_names[3] == "RLEG_JOINT3"
    assert not any(p.endswith("sim.ready") for p in os.listdir(out))
