"""Tests of `servotau identify collect|fit` (servotau/apps/identify.py): the command line end to end on the
inprocess backend (subprocesses), its JSON and motor file, Ctrl-C, and its errors on bad input."""

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from support.identification import short_plan

from servotau.apps.operator_script import write_sim_setup
from servotau.cli import main as cli
from servotau.config import REPO_ROOT
from servotau.hal.log import LogReader, parts_dir
from servotau.identification import MotorParameters
from servotau.identification.plan import load_plan

PYTHON = str(REPO_ROOT / ".venv" / "bin" / "python") if (REPO_ROOT / ".venv").exists() else sys.executable
JOINTS = ["RLEG_JOINT2", "RLEG_JOINT3"]


def servotau(*args, timeout=900):  # [s] a safety net: a loaded machine took over 120 s for a collect
    return subprocess.run([PYTHON, "-m", "servotau.cli", "identify", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, cwd=REPO_ROOT)


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    """`identify collect` of a short plan (17 s of robot time) with matching pushes, then `identify fit --json`, as
    subprocesses."""
    d = tmp_path_factory.mktemp("ident_cli")
    plan_path = d / "plan.toml"
    plan_path.write_text(short_plan(sweep=3.0, hold=3.0))
    sim = write_sim_setup(load_plan(plan_path)[0], d)
    log, motors = d / "log.parquet", d / "motors.toml"
    collect = servotau("collect", "--out", log, "--backend", "inprocess", "--plan", plan_path, "--sim-config", sim)
    assert collect.returncode == 0, collect.stderr
    fit = servotau("fit", log, "--plan", plan_path, "--json", "--out", motors)
    assert fit.returncode == 0, fit.stderr
    return {"dir": d, "plan": plan_path, "sim": sim, "log": log, "motors": motors, "collect": collect, "fit": fit}


def test_collect_writes_a_log_with_frames_commands_and_progress(cli_run):
    """collect records every tick with q_des and ground truth, and prints progress lines with elapsed/total."""
    log = LogReader(cli_run["log"])
    duration = load_plan(cli_run["plan"])[0].duration  # [s] of robot time
    ticks = round(duration / log.info.period)
    assert len(log) == ticks == 17_000
    assert np.isfinite(log.joints("q_des")).all() and np.isfinite(log.joints("q")).all()
    assert log.has_truth and log.metadata["servotau.identification.backend"] == "inprocess"
    out = cli_run["collect"].stdout
    steps = re.findall(rf"\[\s*([\d.]+)/{duration:.1f} s robot", out)
    assert len(steps) >= 6 and float(steps[-1]) == pytest.approx(duration)
    assert "PUSH NOW" in out and f"wrote {cli_run['log']}: {ticks} ticks" in out


def test_fit_json_recovers_the_servo_and_over_estimates_less_than_least_squares(cli_run):
    """fit --json prints one object: per joint, LS within 10 % of the ground-truth reference, asymmetric below it
    and over-estimating held-out samples less often than LS."""
    result = json.loads(cli_run["fit"].stdout)
    assert set(result["joints"]) == set(JOINTS) and result["settings"]["w"] == 100.0
    for j in JOINTS:
        r = result["joints"][j]
        assert r["written"] == "asymmetric"
        ref = r["reference_ground_truth"]["least_squares"]
        for k in ("k_tau", "k_v"):
            assert r["least_squares"]["coefficients"][k] == pytest.approx(ref[k], rel=0.10)
            assert r["asymmetric"]["coefficients"][k] < r["least_squares"]["coefficients"][k]
        assert r["asymmetric"]["heldout"]["overestimation_rate"] < r["least_squares"]["heldout"]["overestimation_rate"]


def test_motor_file_loads_back_with_the_written_values_and_provenance(cli_run):
    """The motor file loads with MotorParameters.load_toml: asymmetric values, held-out metrics, log/date/backend."""
    result = json.loads(cli_run["fit"].stdout)
    assert result["motor_file"] == str(cli_run["motors"])
    params = MotorParameters.load_toml(cli_run["motors"])
    assert list(params) == JOINTS
    for j in JOINTS:
        m, r = params[j], result["joints"][j]["asymmetric"]
        assert m.k_tau == r["coefficients"]["k_tau"] and m.k_v == r["coefficients"]["k_v"]
        assert m.loss.kind == "asymmetric" and m.loss.w == 100.0
        assert m.metrics.n_samples == r["heldout"]["n_samples"]
        assert m.metrics.overestimation_rate == r["heldout"]["overestimation_rate"]
        assert str(cli_run["log"]) in m.provenance and "backend=inprocess" in m.provenance
        assert re.search(r"date=\d{4}-\d\d-\d\d", m.provenance)


def test_fit_options_select_the_written_fit(cli_run, tmp_path, capsys):
    """--loss least_squares --two-stage --joints writes the two-stage least-squares fit of the named joint only."""
    out = tmp_path / "m.toml"
    assert cli(["identify", "fit", str(cli_run["log"]), "--plan", str(cli_run["plan"]), "--loss", "least_squares",
                "--two-stage", "--joints", "RLEG_JOINT3", "--out", str(out), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)["joints"]
    assert list(r) == ["RLEG_JOINT3"] and r["RLEG_JOINT3"]["written"] == "two_stage"
    m = MotorParameters.load_toml(out)["RLEG_JOINT3"]
    assert m.loss.kind == "least_squares" and m.k_tau == r["RLEG_JOINT3"]["two_stage"]["coefficients"]["k_tau"]


def _default_sigint() -> None:  # pragma: no cover - runs in the child
    """Ctrl-C as at a terminal: a test run started in the background (``pytest &``, CI runners) ignores SIGINT,
    the child would inherit that and Python would install no KeyboardInterrupt handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_during_collect_keeps_what_was_recorded(tmp_path):
    """SIGINT in the middle of a collection exits 130 with a complete, readable log of the ticks so far."""
    log = tmp_path / "stopped.parquet"
    p = subprocess.Popen([PYTHON, "-m", "servotau.cli", "identify", "collect", "--out", str(log), "--backend",
                          "inprocess"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO_ROOT,
                         env=dict(os.environ, PYTHONUNBUFFERED="1"), preexec_fn=_default_sigint)
    try:
        deadline = time.monotonic() + 60
        for line in p.stdout:
            if "sweep RLEG_JOINT0" in line or time.monotonic() > deadline:
                break
        time.sleep(1.0)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=300)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, err
    assert "interrupted" in err
    reader = LogReader(log)
    assert len(reader) > 2000 and not parts_dir(log).exists()
    assert np.isfinite(reader.joints("q_des")).all()


@pytest.mark.parametrize("args, message", [
    (["fit", "{d}/missing.parquet"], r"missing\.parquet: no such log file"),
    (["fit", "{log}", "--joints", "RLEG_JOINT3,KNEE"], r'joint "KNEE" is unknown: expected one of'),
    (["fit", "{log}", "--loss", "least_squares", "--w", "10"], r"--w 10.0: expected no weight"),
    (["collect", "--out", "{d}/x.parquet", "--backend", "inprocess", "--joints", "RLEG_JOINT3,LEG7"],
     r'--joints: joint "LEG7" is unknown'),
    (["collect", "--out", "{d}/x.parquet", "--backend", "inprocess", "--plan", "{plan}"],
     r"does not match the plan .*outside every hold window"),
    (["collect", "--out", "{d}/x.parquet", "--hal", "{d}/hal_replay.toml"],
     r'backend = "replay": expected a live robot'),
    (["collect", "--out", "{d}/x.parquet", "--backend", "inprocess", "--sim-config", "nope.toml"],
     r"nope\.toml: config file not found"),
])
def test_cli_errors_name_the_problem_and_write_nothing(cli_run, capsys, args, message):
    """Bad input exits 2 with a message naming the file, field or joint and what was expected; no log is written."""
    fmt = {"d": cli_run["dir"], "log": cli_run["log"], "plan": cli_run["plan"]}
    (cli_run["dir"] / "hal_replay.toml").write_text('[hal]\nbackend = "replay"\n[hal.replay]\nlog = "x.parquet"\n')
    assert cli(["identify", *[a.format(**fmt) for a in args]]) == 2
    assert re.search(message, capsys.readouterr().err)
    assert not Path(cli_run["dir"] / "x.parquet").exists()


def test_cli_error_in_a_subprocess_exits_2_with_the_file_named(tmp_path):
    """`identify fit` on a log without q_des columns fails cleanly (exit 2, stderr names the column)."""
    from servotau.hal.log import LogWriter
    from servotau.simrobot.sim import SimConfig, SimRobot

    robot = SimRobot(SimConfig.named("hanging"))
    path = tmp_path / "no_commands.parquet"
    with LogWriter(path, robot.info, truth=False, extra=[]) as w:
        for _ in range(1200):
            w.append(robot.read(), None)
            robot.step(robot.read().q)
    r = servotau("fit", path, "--joints", "RLEG_JOINT3")
    assert r.returncode == 2
    assert "no_commands.parquet: column 'q_des/RLEG_JOINT3' is NaN in every row" in r.stderr


def test_collect_runs_over_zenoh_against_the_simulated_robot_process(tmp_path):
    """collect on the zenoh backend (a `servotau sim` process) records every tick, the commands and the truth."""
    from support.hal import ENV, free_port, stop_process

    plan_path = tmp_path / "tiny.toml"
    plan_path.write_text('[collect]\njoints = ["RLEG_JOINT3"]\nsettle = 0.5\n[collect.sweep]\nduration = 1.5\n'
                         '[collect.hold]\nmove = 0.5\nhold = 1.0\n[[collect.hold.configurations]]\nRLEG_JOINT3 = 1.2\n')
    sim = write_sim_setup(load_plan(plan_path)[0], tmp_path)
    port, ready, log = free_port(), tmp_path / "ready", tmp_path / "z.parquet"
    server = subprocess.Popen([PYTHON, "-m", "servotau.cli", "sim", "--config", str(sim), "--port", str(port),
                               "--ready-file", str(ready)], env=ENV, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, cwd=REPO_ROOT)
    try:
        deadline = time.monotonic() + 30
        while not ready.exists() and server.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        r = servotau("collect", "--out", log, "--backend", "zenoh", "--port", port, "--plan", plan_path, timeout=900)
    finally:
        stop_process(server)
    assert r.returncode == 0, r.stderr
    reader = LogReader(log)
    assert len(reader) == 4500 and reader.has_truth
    assert reader.metadata["servotau.identification.backend"] == "zenoh"
    assert np.isfinite(reader.joints("q_des")).all() and np.all(np.diff(reader.columns["seq"]) == 1)
