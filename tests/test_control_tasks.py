"""Task files, trajectory tables, references and the feasibility check (control/tasks/), without running a loop."""

from __future__ import annotations

import sys
import textwrap

import numpy as np
import pytest

from servotau.control.tasks import FileTask, InfeasibleTask, TaskRunner, import_task, load_table, load_task
from servotau.control.trajectory import JerkLimitedSegment, stopping_segment
from servotau.errors import ConfigError

SHIPPED = ("hold", "swing", "force", "identification", "table_example")


@pytest.fixture(scope="module")
def robot():
    """(RobotInfo, half-sitting posture) of the simulated HRP-2."""
    from servotau.simrobot.sim import SimConfig, SimRobot

    sim = SimRobot(SimConfig.named("hanging", seed=0))
    return sim.info, sim.read().q.copy()


def write(tmp_path, text: str, name: str = "task.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


class HoldWithGains:
    """A user's task class (no file): one torque phase "soft" holding the start posture with ``gains``."""

    name, settle, ft_offsets, source = "mine", 0.5, "calibrate", "mine.py"

    def __init__(self, gains):
        self.gains = gains

    def phases(self, info, q):
        from servotau.control.tasks import Phase
        from servotau.control.tasks.references import Hold

        return [Phase("soft", Hold(q), "torque", 0.1, gains=self.gains)]


SINE = """
    name = "t"
    [[phases]]
    name = "wave"
    duration = 1.0
    [phases.reference]
    type = "sinusoid"
    [phases.reference.joints.RLEG_JOINT3]
    amplitude = {amplitude}
    frequency = {frequency}
    """


@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_task_reads_and_is_feasible_from_half_sitting(robot, name):
    info, q = robot
    phases = TaskRunner(FileTask.load(name), info).prepare(q)
    assert phases and all(p.mode in ("position", "torque") for p in phases)


def test_the_swing_task_is_the_paper_swing(robot):
    """config/tasks/swing.toml reproduces control/trajectory.right_leg_swing sample by sample."""
    from servotau.control.trajectory import right_leg_swing

    info, q = robot
    phase = TaskRunner(FileTask.load("swing", duration=2.5), info).prepare(q)[0]
    swing = right_leg_swing(info.joint_names, q, 2.5)
    for t in np.linspace(0, 2.5, 37):
        a, b = phase.reference.sample(t), swing.sample(t)
        assert np.allclose(a.q, b.q) and np.allclose(a.dq, b.dq) and np.allclose(a.ddq, b.ddq)


def test_a_bad_field_names_the_file_the_phase_and_the_field(tmp_path):
    with pytest.raises(ConfigError, match=r"task.toml: field 'phases.wave.reference.joints.RLEG_JOINT3.frequency' "
                                          r"= -1.0: expected a finite number > 0 \[Hz\]"):
        load_task(write(tmp_path, SINE.format(amplitude=0.1, frequency=-1.0)))
    with pytest.raises(ConfigError, match=r"field 'phases.wave.mode' = 'force': expected one of"):
        load_task(write(tmp_path, SINE.format(amplitude=0.1, frequency=1).replace('name = "wave"',
                                                                                   'name = "wave"\nmode = "force"')))


def test_gains_per_phase_are_converted_per_joint_and_bad_ones_refused_naming_the_phase(tmp_path, robot):
    """Each torque phase has its own gains (K6 = 0.5 then 0.25: k_s per joint from its motor model); gains in a
    position phase or a user task's unknown or negative gain are refused, naming the phase and the field, before
    anything moves (gains the identified model predicts unstable: the next test)."""

    text = SINE.format(amplitude=0.1, frequency=1).replace('name = "wave"', 'name = "wave"\nk6 = 0.5')
    with pytest.raises(ConfigError, match=r"field 'phases.wave.k6' = 0.5: expected no gains in a position phase"):
        load_task(write(tmp_path, text))
    text = """
        [[phases]]
        name = "a"
        mode = "torque"
        k6 = 0.5
        duration = 0.1
        [[phases]]
        name = "b"
        mode = "torque"
        k6 = {k6}
        duration = 0.1
        [[phases]]
        name = "c"
        duration = 0.1
        """
    runner = TaskRunner(FileTask(load_task(write(tmp_path, text.format(k6=0.25)))), robot[0])
    runner.prepare(robot[1])
    motors = runner.manager().config.motors
    for g, k6 in zip(runner.gains[:2], (0.5, 0.25), strict=True):
        for j, m in motors.items():
            i = robot[0].joint_index(j)
            assert m.k_tau * (1 + g.k_p[i]) * g.k_s[i] == pytest.approx(k6)
    assert runner.gains[2] is None  # a position phase keeps the gains in use

    with pytest.raises(ConfigError, match=r'mine.py: phase "soft": gain \'k9\': expected one of'):
        TaskRunner(HoldWithGains({"k9": 1.0}), robot[0]).prepare(robot[1])
    with pytest.raises(ConfigError, match=r'mine.py: phase "soft": gain k_s = -1.0: expected a finite number >= 0'):
        TaskRunner(HoldWithGains({"k_s": -1.0}), robot[0]).prepare(robot[1])


def test_phase_gains_are_scheduled_and_a_loop_the_model_predicts_unstable_is_refused(robot):
    """A phase's velocity gain (k7 or k_d) replaces control.toml's k7_per_k_v; k_p follows the margin schedule
    (gain_schedule = "margin"); K7 = 0 leaves the servo's damping cancelled by the k_v feedforward, which the
    identified model predicts unstable: refused naming the phase, the motor file and the joint, before anything
    moves."""
    info, q = robot
    runner = TaskRunner(HoldWithGains({"k6": 1.0, "k7": 0.01}), info)
    runner.prepare(q)
    motors, (g,) = runner.manager().config.motors, runner.gains
    for j, m in motors.items():
        i = info.joint_index(j)
        assert g.k_p[i] in (0.0, 0.125, 0.25, 0.5)  # control.toml's k_p = 0.5, halved where the margin is short
        assert m.k_tau * (1 + g.k_p[i]) * g.k_d[i] == pytest.approx(0.01)  # K7 as given
    with pytest.raises(ConfigError, match=r'mine.py: phase "soft": .*hrp2_sim_deadband.toml: joint '
                                                r'"RLEG_JOINT\d".*predicts an unstable torque loop'):
        TaskRunner(HoldWithGains({"k6": 1.0, "k7": 0.0}), info).prepare(q)


def test_an_unknown_joint_is_refused_naming_it(tmp_path, robot):
    task = FileTask(load_task(write(tmp_path, SINE.format(amplitude=0.1, frequency=1).replace("RLEG_JOINT3",
                                                                                              "RLEG_JOINT9"))))
    with pytest.raises(ConfigError, match=r'phase "wave": joint "RLEG_JOINT9" is not a joint of the robot'):
        TaskRunner(task, robot[0]).prepare(robot[1])


def test_beyond_a_joint_limit_is_refused_naming_phase_joint_and_limit(tmp_path, robot):
    task = FileTask(load_task(write(tmp_path, SINE.format(amplitude=2.0, frequency=0.1))))
    with pytest.raises(InfeasibleTask, match=r'phase "wave": joint RLEG_JOINT3 reaches -1.127 rad, beyond its lower '
                                             r"limit -0.015 rad \(q_min \+ joint_limit_margin 0.02 rad\)"):
        TaskRunner(task, robot[0]).prepare(robot[1])


def test_too_fast_is_refused_naming_the_velocity_limit(tmp_path, robot):
    task = FileTask(load_task(write(tmp_path, SINE.format(amplitude=0.5, frequency=3.0))))
    with pytest.raises(InfeasibleTask, match=r'phase "wave": joint RLEG_JOINT3 moves at 9.42 rad/s.*, above 4.70 '
                                             r"rad/s = \(1 - 0.06, position mode\) x the velocity limit 5 rad/s"):
        TaskRunner(task, robot[0]).prepare(robot[1])


def test_a_swing_too_short_is_refused_with_the_duration_it_needs(robot):
    """The duration the refusal asks for is accepted (the speed the estimator reads, with the margin)."""
    with pytest.raises(InfeasibleTask, match=r'swing.toml: phase "swing": joint RLEG_JOINT3 moves at 6.42 rad/s '
                                             r".*expected a duration of at least (\d\.\d\d) s") as refused:
        TaskRunner(FileTask.load("swing", duration=1.2), robot[0]).prepare(robot[1])
    need = float(str(refused.value).rsplit("at least ", 1)[1].split(" s")[0])
    assert 1.6 < need < 1.7
    TaskRunner(FileTask.load("swing", duration=need), robot[0]).prepare(robot[1])


def test_the_speed_the_estimator_reads_and_the_command_error_are_predicted_before_anything_moves(tmp_path, robot):
    """A knee sinusoid at 7 Hz whose reference stays under the velocity limit is refused on the speed its encoder
    filter will read (it tripped joint_velocity when run, CHANGELOG); with a command-error limit of 0.03 rad the
    2 s swing (0.0247 rad predicted on the knee) is refused naming the joint, the value and the limit."""
    from servotau.config import CONFIG_DIR

    fast = SINE.format(amplitude=0.1, frequency=7.0).replace("frequency = 7.0", "frequency = 7.0\n    ramp = 0.5")
    with pytest.raises(InfeasibleTask, match=r'phase "wave": joint RLEG_JOINT3 moves at 4.60 rad/s \(the estimator '
                                             r"reads 6.\d\d rad/s: the servo's response through its filter\), above "
                                             r"4.70 rad/s"):
        TaskRunner(FileTask(load_task(write(tmp_path, fast))), robot[0]).prepare(robot[1])
    control = (CONFIG_DIR / "control.toml").read_text().replace("max_command_error = 0.08", "max_command_error = 0.03")
    control = control.replace('motors = "motors/', f'motors = "{CONFIG_DIR}/motors/')
    (tmp_path / "control.toml").write_text(control)
    runner = TaskRunner(FileTask.load("swing", duration=2.0), robot[0], control=tmp_path / "control.toml")
    with pytest.raises(InfeasibleTask, match=r'phase "swing": joint RLEG_JOINT3 needs a command error \|q_des - q\| '
                                             r"of 0.02\d rad at t = .*above 0.022 rad = \(1 - 0.25\) x the safety's "
                                             r"max_command_error 0.03 rad"):
        runner.prepare(robot[1])


def test_a_jerk_limited_phase_shorter_than_its_trajectory_is_refused(tmp_path, robot):
    text = """
        [[phases]]
        name = "reach"
        duration = 0.2
        [phases.reference]
        type = "waypoints"
        max_velocity = 1.0
        [[phases.reference.waypoints]]
        RLEG_JOINT3 = { delta = 0.5 }
        """
    task = FileTask(load_task(write(tmp_path, text)))
    with pytest.raises(InfeasibleTask, match=r'phase "reach": duration 0.2 s is shorter than its time-optimal '
                                             r"trajectory \(0.800 s within max_velocity, max_acceleration, "
                                             r"max_jerk\): expected >= 0.800 s"):
        TaskRunner(task, robot[0]).prepare(robot[1])


def test_a_jerk_limited_move_keeps_its_bounds_and_arrives_together():
    seg = JerkLimitedSegment([0.0, 0.0, 1.0], [1.0, -0.5, 1.0], 2.0, 10.0, 100.0)
    ts = np.linspace(0, seg.duration, 400)
    q, dq, ddq = (np.array(x) for x in zip(*(seg.sample(t) for t in ts), strict=True))
    assert np.allclose(q[-1], [1.0, -0.5, 1.0]) and np.allclose(dq[-1], 0) and np.allclose(q[:, 2], 1.0)
    assert np.abs(dq).max() <= 2.0 + 1e-9 and np.abs(ddq).max() <= 10.0 + 1e-9
    assert 0.79 < seg.duration < 0.81  # 1 rad at 2 rad/s with 0.2 s ramps: the time-optimal 0.8 s
    stop = stopping_segment([0.0], [1.0], [0.0], 5.0, 50.0)
    assert np.allclose(stop.sample(stop.duration)[1], 0) and stop.q1[0] > 0


TABLE = "t,RLEG_JOINT2,RLEG_JOINT3\n0,0,0\n0.5,-0.1,0.2\n1.0,0,0\n"


def test_a_table_with_a_misspelled_column_names_it_and_the_closest_joint(tmp_path, robot):
    path = tmp_path / "m.csv"
    path.write_text(TABLE.replace("RLEG_JOINT3", "RLEG_JIONT3"))
    with pytest.raises(ConfigError, match=r'm.csv: column "RLEG_JIONT3" is not a joint of the robot \(did you mean '
                                          r'"RLEG_JOINT3"\?\)'):
        load_table(path, robot[0].joint_names)


def test_a_table_missing_a_column_of_the_task_names_it(tmp_path, robot):
    (tmp_path / "m.csv").write_text(TABLE)
    text = """
        [[phases]]
        name = "play"
        [phases.reference]
        type = "table"
        file = "m.csv"
        relative = true
        joints = ["RLEG_JOINT2", "RLEG_JOINT3", "RLEG_JOINT4"]
        """
    task = FileTask(load_task(write(tmp_path, text)))
    with pytest.raises(ConfigError, match=r'phase "play": .*m.csv: no column "RLEG_JOINT4": expected a column for each '
                                          r"joint of the task"):
        TaskRunner(task, robot[0]).prepare(robot[1])


def test_a_phase_shorter_than_its_table_is_refused(tmp_path, robot):
    (tmp_path / "m.csv").write_text(TABLE)
    text = """
        [[phases]]
        name = "play"
        duration = 0.5
        [phases.reference]
        type = "table"
        file = "m.csv"
        relative = true
        """
    with pytest.raises(InfeasibleTask, match=r'phase "play": duration 0.5 s is shorter than its table .*m.csv \(1 s\)'):
        TaskRunner(FileTask(load_task(write(tmp_path, text))), robot[0]).prepare(robot[1])


def test_a_table_reads_from_parquet_as_from_csv(tmp_path, robot):
    import pyarrow as pa
    import pyarrow.parquet as pq

    (tmp_path / "m.csv").write_text(TABLE)
    pq.write_table(pa.table({"t": [0.0, 0.5, 1.0], "RLEG_JOINT2": [0.0, -0.1, 0.0], "RLEG_JOINT3": [0.0, 0.2, 0.0]}),
                   tmp_path / "m.parquet")
    a, b = (load_table(tmp_path / f, robot[0].joint_names) for f in ("m.csv", "m.parquet"))
    assert a.joints == b.joints and np.allclose(a.q, b.q) and np.allclose(a.t, b.t)


def test_an_absolute_table_far_from_the_start_is_refused(tmp_path, robot):
    (tmp_path / "m.csv").write_text(TABLE)
    text = """
        [[phases]]
        name = "play"
        [phases.reference]
        type = "table"
        file = "m.csv"
        """
    with pytest.raises(InfeasibleTask, match=r'phase "play": the table .*m.csv starts 0.873 rad away from the posture '
                                             r"at the phase start on RLEG_JOINT3"):
        TaskRunner(FileTask(load_task(write(tmp_path, text))), robot[0]).prepare(robot[1])


def test_a_user_task_by_import_path_and_the_errors_when_it_cannot_be(tmp_path, monkeypatch, robot):
    (tmp_path / "mytasks.py").write_text(textwrap.dedent("""
        from servotau.control.tasks import Hold, Phase, Task

        class Still(Task):
            name = "still"

            def phases(self, info, q_start):
                return [Phase("still", Hold(q_start), duration=0.1)]

        class NoPhases:
            name = "none"
        """))
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        task = import_task("mytasks:Still")
        assert task.name == "still" and TaskRunner(task, robot[0]).prepare(robot[1])[0].length == 0.1
        with pytest.raises(ConfigError, match=r"--task mytasks:NoPhases: NoPhases lacks phases: expected a task"):
            import_task("mytasks:NoPhases")
        with pytest.raises(ConfigError, match=r"module mytasks has no attribute Missing"):
            import_task("mytasks:Missing")
        with pytest.raises(ConfigError, match=r"cannot import module nosuchpkg_xyz.tasks \(ModuleNotFoundError"):
            import_task("nosuchpkg_xyz.tasks:Task")
    finally:
        sys.modules.pop("mytasks", None)


def test_a_reference_jump_between_phases_is_refused(robot):
    """A Python task whose second phase does not start where the first ends (a sinusoid cut mid-period)."""
    from servotau.control.tasks import Hold, Phase, Sinusoids, Task, Wave

    class Cut(Task):
        def phases(self, info, q):
            wave = Sinusoids(q, info.joint_names, {"RLEG_JOINT3": Wave(0.05, 1.0)})
            return [Phase("wave", wave, duration=0.25), Phase("hold", Hold(q), duration=0.1)]

    with pytest.raises(InfeasibleTask, match=r'phase "hold" starts 0.050 rad away from where phase "wave" ends on '
                                             r"RLEG_JOINT3"):
        TaskRunner(Cut(), robot[0]).prepare(robot[1])


def test_a_config_folders_control_file_finds_its_own_motor_file_and_task_names_skip_the_working_folder(
        robot, tmp_path, monkeypatch):
    """The task's controller config reads the motor file next to its control.toml (a --config folder), and a bare
    task name never reads ./tasks/NAME.toml of the working folder."""
    import shutil

    from servotau.config import CONFIG_DIR
    from servotau.control.tasks.build import task_control_config
    from servotau.control.tasks.spec import task_path

    info, _ = robot
    (tmp_path / "motors").mkdir()
    shutil.copy(CONFIG_DIR / "motors" / "hrp2_sim_deadband.toml", tmp_path / "motors" / "only_here.toml")
    text = (CONFIG_DIR / "control.toml").read_text()
    (tmp_path / "control.toml").write_text(text.replace("motors/hrp2_sim_deadband.toml", "motors/only_here.toml"))
    config = task_control_config(info, {}, None, tmp_path / "control.toml")
    assert config.motors  # read from tmp_path/motors/only_here.toml (not among the packaged defaults)
    work = tmp_path / "work"
    (work / "tasks").mkdir(parents=True)
    (work / "tasks" / "swing.toml").write_text("not toml [")
    monkeypatch.chdir(work)
    assert task_path("swing") == CONFIG_DIR / "tasks" / "swing.toml"
