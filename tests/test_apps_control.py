"""servotau control with tasks, in process: Ctrl-C stops smoothly with the log closed and the status line printed;
an infeasible task or one that cannot be imported is refused (exit code 2) before anything moves."""

from __future__ import annotations

import sys
import textwrap

import numpy as np
import pytest

from servotau.apps.control import main as control_main
from servotau.cli import build_parser
from servotau.hal import LogReader
from servotau.hal.log import parts_dir

INTERRUPTED = """
    import os
    import signal

    from servotau.control.tasks import Hold, Phase, Task


    class Interrupted(Hold):
        '''Holds; at 0.5 s of robot time into its phase, Ctrl-C (SIGINT to this process, once).'''

        sent = False

        def sample(self, t):
            if t >= 0.5 and not Interrupted.sent:
                Interrupted.sent = True
                os.kill(os.getpid(), signal.SIGINT)
            return super().sample(t)


    class Task(Task):
        name = "interrupted"
        settle = 0.2

        def phases(self, info, q_start):
            return [Phase("hold", Interrupted(q_start))]
    """


def control(*argv):
    return control_main(build_parser("control").parse_args(["control", "--backend", "inprocess", *argv]))


def test_ctrl_c_stops_smoothly_and_closes_the_log(tmp_path, monkeypatch, capsys):
    (tmp_path / "interrupted_task.py").write_text(textwrap.dedent(INTERRUPTED))
    monkeypatch.syspath_prepend(str(tmp_path))
    log = tmp_path / "run.parquet"
    try:
        code = control("--task", "interrupted_task:Task", "--log", str(log), "--save-ft-offsets",
                       str(tmp_path / "ft.toml"))
    finally:
        sys.modules.pop("interrupted_task", None)
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "stopped in phase hold: the reference at rest, position mode" in out
    assert "t 1.0 s  position  phase 1/1 hold  |q_ref-q| max" in out  # the status line, once a second
    assert "|tau_d-tau_hat| -  stopping" in out
    assert log.exists() and not parts_dir(log).exists()
    reader = LogReader(log)
    assert len(reader.columns["t"]) == 200 + 501 + 501 and reader.has_truth  # settle, to the stop, stop + fade
    from servotau.apps.control import load_ft_offsets  # the offsets calibrated while settling, for --ft-offsets

    offsets = load_ft_offsets(str(tmp_path / "ft.toml"), reader.info)([])
    assert offsets.shape == (4, 6) and np.all(np.isfinite(offsets)) and np.abs(offsets).max() > 0
    from servotau.identification.workbench import load_dataset  # the workbench reads the truth it maps

    ds = load_dataset(log, joint="RLEG_JOINT3", roles={"torque": "true/tau/RLEG_JOINT3"})
    true = reader.columns["true/tau/RLEG_JOINT3"][-len(ds.signals["tau"]):]  # after the rows it drops
    est = reader.columns["est/tau/RLEG_JOINT3"][-len(ds.signals["tau"]):]
    assert np.abs(ds.signals["tau"] - true).max() < 0.01 < np.abs(ds.signals["tau"] - est).max()  # [N m] smoothed


def test_ft_offsets_from_a_file_name_the_sensor(tmp_path):
    from servotau.apps.control import load_ft_offsets
    from servotau.simrobot.sim import SimConfig, SimRobot

    info = SimRobot(SimConfig.named("hanging", seed=0)).info
    rows = {s: [float(i), 0, 0, 0, 0, 0] for i, s in enumerate(info.ft_sensor_names)}
    path = tmp_path / "ft.toml"
    path.write_text("\n".join(f"{s} = {v}" for s, v in rows.items()))
    assert np.array_equal(load_ft_offsets(str(path), info)([]), np.array(list(rows.values())))
    path.write_text(f"{info.ft_sensor_names[0]} = [1, 2, 3]")
    with pytest.raises(Exception, match=rf"field '{info.ft_sensor_names[0]}' = \[1, 2, 3\]: expected a list of 6"):
        load_ft_offsets(str(path), info)


def test_an_infeasible_task_is_refused_before_anything_moves(tmp_path, capsys):
    log = tmp_path / "run.parquet"
    assert control("--task", "swing", "--duration", "1.2", "--log", str(log)) == 2
    err = capsys.readouterr().err
    assert 'phase "swing": joint RLEG_JOINT3 moves at 6.42 rad/s (the estimator reads 6.48 rad/s' in err
    assert "above 4.70 rad/s = (1 - 0.06, position mode) x the velocity limit 5 rad/s" in err
    assert "expected a duration of at least 1.66 s" in err
    assert not log.exists() or len(LogReader(log).columns["t"]) == 0


@pytest.mark.parametrize("task, message", [
    ("nosuchpkg_xyz:Task", "cannot import module nosuchpkg_xyz (ModuleNotFoundError"),
    ("no_such_task", "task no_such_task: no such task file"),
    ("hold", "--duration 2: this task has no duration_phase to set"),
])
def test_a_task_that_cannot_be_loaded_is_a_one_line_error(task, message, capsys):
    argv = ["--task", task] + (["--duration", "2"] if task == "hold" else [])
    assert control(*argv) == 2
    assert message in capsys.readouterr().err


def test_the_log_keeps_truth_columns_when_the_first_frames_have_none(tmp_path):
    """Over Zenoh the truth of the first frame never arrives: the log hook holds the rows back until a row has
    truth (those before it hold NaN there); a backend without truth gives a log without true/* columns."""
    from types import SimpleNamespace

    from servotau.apps.control import LogHook
    from servotau.hal.log import LogWriter
    from servotau.simrobot.sim import SimConfig, SimRobot

    sim = SimRobot(SimConfig.named("hanging", seed=0))
    for truth_from, path in ((3, tmp_path / "late.parquet"), (None, tmp_path / "none.parquet")):
        writer = LogWriter(path, sim.info)
        hook = LogHook(writer)
        for k in range(6):
            frame = sim.read()
            truth = sim.ground_truth() if truth_from is not None and k >= truth_from else None
            est = SimpleNamespace(tau=np.zeros(sim.info.nq), dq=np.zeros(sim.info.nq))
            hook.on_tick(SimpleNamespace(frame=frame, terms=SimpleNamespace(q_des=frame.q), truth=truth, estimate=est))
            sim.step(frame.q)
        hook.flush()
        writer.close()
        reader = LogReader(path)
        assert len(reader.columns["t"]) == 6
        if truth_from is None:
            assert not any(c.startswith("true/") for c in reader.columns)
        else:
            tau = reader.joints("true/tau")
            assert np.isnan(tau[:3]).all() and np.isfinite(tau[3:]).all()
