"""Tasks end to end on the in-process simulator: the shipped tasks (cut short: FileTask.shortened, the settle
phase 0.2 s; the swing and the table example in tests/test_apps.py and tests/test_control_tasks_example.py, the hold
and Ctrl-C in tests/test_apps_control.py), an infeasible task refused with nothing sent, a bumpless mode switch by
the operator and the smooth stop, an operator's start of another task."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from servotau.control.loop import ControlLoop, LoopHook
from servotau.control.operator import OperatorChannel
from servotau.control.tasks import FileTask, InfeasibleTask, TaskRunner
from servotau.hal.backends.inprocess import InProcessBackend
from servotau.simrobot.sim import SimConfig, SimRobot

SETTLE = 0.2  # [s] of the shortened tasks


class Counting(InProcessBackend):
    """Counts the commands written."""

    writes = 0

    def write(self, q_des):
        self.writes += 1
        return super().write(q_des)


class Record(LoopHook):
    """q_des, mode and the phase of every tick; calls ``at(tick)`` if given."""

    def __init__(self, runner=None, at=None):
        self.runner, self.at = runner, at
        self.q_des, self.modes, self.phases, self.t = [], [], [], []

    def on_tick(self, tick):
        self.q_des.append(tick.terms.q_des.copy())
        self.modes.append(tick.terms.mode)
        self.t.append(tick.t)
        if self.runner is not None:
            self.phases.append(self.runner.phase_name)
        if self.at is not None:
            self.at(tick)


def run(task, scenario="hanging", ft_offsets=None, hooks=(), operator=None):
    backend = Counting(SimRobot(SimConfig.named(scenario, seed=0)))
    try:
        runner = TaskRunner(task, backend.info)
        record = Record(runner)
        loop = ControlLoop(backend, runner.manager(), hooks=[runner, record, *hooks], settle=task.settle,
                           ft_offsets=runner.ft_offsets(ft_offsets))
        result = runner.run(loop, operator=operator)
        return result, runner, record, backend
    finally:
        backend.close()


@pytest.mark.slow
@pytest.mark.parametrize("name, duration", [("swing", 2.0), ("table_example", None)])
def test_a_shipped_motion_task_runs_to_its_end(name, duration):
    """(In the default suite the swing runs through servotau control's session, tests/test_apps.py, and the table
    example through examples/run_task.py, tests/test_control_tasks_example.py.)"""
    result, runner, record, _ = run(FileTask.load(name, duration).shortened(0.25, settle=SETTLE))
    assert result.end == "completed" and result.tripped is None
    assert runner.phase_name == "done" and record.phases[-1] == "tail"
    assert set(record.phases) == {"settle", "swing" if name == "swing" else "table", "tail"}


def test_the_force_task_runs_in_torque_mode_with_its_force_reference():
    """The paper's force task (shortened: 0.25 s hold, 0.25 s of the sinusoid), right foot on the block, F/T offsets
    from the same robot hanging (settle.ft_offsets = "external")."""
    from servotau.control.loop import estimator_config
    from servotau.experiments.common import ft_offsets_hanging

    task = FileTask.load("force").shortened(0.25, settle=SETTLE)
    with pytest.raises(Exception, match='ft_offsets = "external": expected F/T offsets from the caller'):
        TaskRunner(task, SimRobot(SimConfig.named("force", seed=0)).info).ft_offsets(None)
    offsets = ft_offsets_hanging(0, estimator_config())
    f_d = []
    probe = Record(at=lambda tick: f_d.append(tick.terms.f_d[2]))
    result, runner, record, _ = run(task, "force", lambda frames: offsets, hooks=[probe])
    assert result.end == "completed" and result.tripped is None
    assert record.modes[-1] == "torque" and runner.manager().config.force is not None
    t, f = np.array(record.t), np.array(f_d)
    force = t >= 0.25 - 1e-9
    f0 = f[force][0]  # the start value, then f0 + 40 sin(2 pi 0.5 t)
    assert f[force][-1] - f0 == pytest.approx(40 * np.sin(np.pi * (t[force][-1] - t[force][0])), abs=1e-6)


def test_the_identification_task_sweeps_then_returns():
    """Its first sweep (the increasing-amplitude sinusoid) and return (min-jerk), stopped after them; the whole
    sequence is the slow test below."""
    stop = {}

    def at(tick):
        if stop["runner"].index >= 2 and "done" not in stop:
            stop["done"] = True
            stop["loop"].request_stop()

    task = FileTask.load("identification").shortened(0.25, settle=SETTLE)
    backend = InProcessBackend(SimRobot(SimConfig.named("hanging", seed=0)))
    try:
        runner = TaskRunner(task, backend.info)
        stop["runner"] = runner
        record = Record(runner, at)
        loop = ControlLoop(backend, runner.manager(), hooks=[runner, record], settle=task.settle)
        stop["loop"] = loop
        result = runner.run(loop)
    finally:
        backend.close()
    assert result.end == "stopped" and result.tripped is None
    assert {"sweep_0", "return_0"} <= set(record.phases)
    j = backend.info.joint_index("RLEG_JOINT0")
    q = np.array(record.q_des)[:, j]
    assert np.ptp(q) > 0.01  # [rad] the sweep moved hip yaw (0.25 s of it, amplitude 0.02 rad fading in over 0.5 s)


@pytest.mark.slow
def test_the_whole_identification_task_runs_shortened():
    result, runner, record, _ = run(FileTask.load("identification").shortened(0.25, settle=SETTLE))
    assert result.end == "completed" and result.tripped is None and runner.phase_name == "done"
    assert len(set(record.phases) - {"settle"}) == 18


def test_an_infeasible_task_sends_nothing():
    backend = Counting(SimRobot(SimConfig.named("hanging", seed=0)))
    try:
        runner = TaskRunner(FileTask.load("swing", duration=1.2), backend.info)
        loop = ControlLoop(backend, runner.manager(), hooks=[runner])
        with pytest.raises(InfeasibleTask, match=r'phase "swing": joint RLEG_JOINT3 moves at 6.42 rad/s'):
            runner.run(loop)
        assert backend.writes == 0 and backend.robot.seq == 0
    finally:
        backend.close()


def test_the_operator_switches_to_torque_bumplessly_then_stops():
    """``torque`` from another thread (servotau ctl's path) while holding: the command does not jump at the switch
    (the offset fades); then ``stop`` returns to position mode and ends the run."""
    channel = OperatorChannel()
    sent = {}

    def at(tick):
        if "torque" not in sent and tick.t >= 0.1:
            sent["torque"] = threading.Thread(target=lambda: sent.setdefault("answer", channel.request("torque", 30)))
            sent["torque"].start()
        if tick.terms.mode == "torque" and "t_switch" not in sent:
            sent["t_switch"] = tick.t
        if "t_switch" in sent and tick.t >= sent["t_switch"] + 0.3 and "stop" not in sent:
            sent["stop"] = threading.Thread(target=lambda: sent.setdefault("stopped", channel.request("stop", 30)))
            sent["stop"].start()

    result, runner, record, _ = run(FileTask.load("hold").shortened(0.25, settle=SETTLE), operator=channel,
                                    hooks=[Record(at=at)])
    for th in (sent["torque"], sent["stop"]):
        th.join(10)
    assert sent["answer"].ok and sent["stopped"].ok and result.end == "stopped" and result.tripped is None
    modes = record.modes
    k = modes.index("torque")
    steps = np.abs(np.diff(np.array(record.q_des), axis=0)).max(axis=1)
    assert steps[k - 5:k + 5].max() < 2e-4, steps[k - 5:k + 5]  # [rad] per tick, across the switch
    assert modes[-1] == "position"


WAVE = """
name = "wave"
[[phases]]
name = "wave"
duration = 0.3
[phases.reference]
type = "sinusoid"
[phases.reference.joints.RLEG_JOINT3]
amplitude = 0.05
frequency = 2.0
ramp = 0.1
"""


def test_the_operator_starts_another_task_from_rest(tmp_path):
    """``start`` while holding: the new task (a file) begins where the reference rests and runs to its end; a task
    that cannot be read is refused with the reason, nothing changed. The loop's thread never reads nor builds a
    task: a worker does (TaskRunner.build), and the loop answers once it is done."""
    (tmp_path / "wave.toml").write_text(WAVE)
    channel = OperatorChannel()
    answers = {}
    builders, loop_thread = [], []

    class Watch(LoopHook):
        def on_tick(self, tick):
            loop_thread[:] = [threading.get_ident()]

    real_build = TaskRunner.build

    def build(self, task, q_start):
        if loop_thread:  # once the loop runs
            builders.append(threading.get_ident())
        return real_build(self, task, q_start)

    real_resolve = TaskRunner.__init__.__kwdefaults__["resolve"]

    def resolve(name):
        if loop_thread:
            builders.append(threading.get_ident())
        return real_resolve(name)

    def at(tick):
        if tick.t >= 0.05 and "bad" not in answers:
            answers["bad"] = threading.Thread(
                target=lambda: answers.setdefault("refused", channel.request("start", 30, task="no_such_task")))
            answers["bad"].start()
        if "refused" in answers and "good" not in answers:
            answers["good"] = threading.Thread(
                target=lambda: answers.setdefault("ok", channel.request("start", 30, task=str(tmp_path / "wave.toml"))))
            answers["good"].start()

    mp = pytest.MonkeyPatch()
    mp.setattr(TaskRunner, "build", build)
    mp.setattr(TaskRunner.__init__, "__kwdefaults__", {**TaskRunner.__init__.__kwdefaults__, "resolve": resolve})
    try:
        result, runner, record, _ = run(FileTask.load("hold").shortened(0.25, settle=SETTLE), operator=channel,
                                        hooks=[Record(at=at), Watch()])
    finally:
        mp.undo()
    answers["good"].join(10)
    assert answers["ok"].ok, answers["ok"]
    assert not answers["refused"].ok and "start no_such_task: " in answers["refused"].error
    assert result.end == "completed" and result.tripped is None and record.phases[-1] == "wave"
    assert runner.task.name == "wave"
    assert len(builders) == 3 and loop_thread[0] not in builders  # 2 reads, 1 build (the bad task is not read)


def test_a_start_whose_build_raises_anything_or_hangs_is_refused_and_the_run_goes_on(monkeypatch):
    """A user's task that raises SystemExit while it is built, or never finishes building: the start is refused
    with the reason (the second after START_BUILD_LIMIT of robot time), the worker never blocks the loop, and the
    running task (a hold) goes on until stopped."""
    import servotau.control.tasks.runner as runner_module

    monkeypatch.setattr(runner_module, "START_BUILD_LIMIT", 0.05)
    channel, answers, never = OperatorChannel(), {}, threading.Event()

    def resolve(name):
        if name == "exits":
            raise SystemExit(2)
        never.wait(30)  # "hangs": released at the end of the test
        raise RuntimeError("late")

    def ask(key, name):
        answers[key] = threading.Thread(target=lambda: answers.setdefault(key + "_answer",
                                                                           channel.request("start", 30, task=name)))
        answers[key].start()

    def at(tick):
        if tick.t >= 0.05 and "exits" not in answers:
            ask("exits", "exits")
        if "exits_answer" in answers and "hangs" not in answers:
            ask("hangs", "hangs")
        if "hangs_answer" in answers and "stop" not in answers:  # the hold runs until stopped
            answers["stop"] = channel.post("stop")

    monkeypatch.setattr(TaskRunner.__init__, "__kwdefaults__", {**TaskRunner.__init__.__kwdefaults__,
                                                                 "resolve": resolve})
    try:
        result, runner, _, _ = run(FileTask.load("hold").shortened(0.5, settle=SETTLE), operator=channel,
                                   hooks=[Record(at=at)])
    finally:
        never.set()
    answers["hangs"].join(10)
    assert not answers["exits_answer"].ok and "SystemExit" in answers["exits_answer"].error
    assert not answers["hangs_answer"].ok and "not built within 0.05 s of robot time" in answers["hangs_answer"].error
    assert result.end == "stopped" and result.tripped is None and runner.task.name == "hold"


REST = """
name = "rest"
[[phases]]
name = "rest"
duration = 0.1
[phases.reference]
type = "hold"
"""


def test_a_start_while_the_reference_moves_is_built_again_where_it_comes_to_rest(tmp_path):
    """``start`` during a wave: built on where the reference would rest at the request, then (the reference having
    moved on) built again on where the stop begun then rests; the new task runs from there, the command without a
    jump."""
    (tmp_path / "wave.toml").write_text(WAVE.replace("duration = 0.3", "duration = 2.0"))
    (tmp_path / "rest.toml").write_text(REST)
    channel = OperatorChannel()
    answers = {}

    def at(tick):
        if tick.t >= 0.12 and "start" not in answers:
            answers["start"] = threading.Thread(
                target=lambda: answers.setdefault("ok", channel.request("start", 30, task=str(tmp_path / "rest.toml"))))
            answers["start"].start()

    result, runner, record, _ = run(FileTask.load(str(tmp_path / "wave.toml")), operator=channel,
                                    hooks=[Record(at=at)])
    answers["start"].join(10)
    assert answers["ok"].ok, answers["ok"]
    assert result.end == "completed" and result.tripped is None and runner.task.name == "rest"
    assert record.phases[-1] == "rest" and "stop" in record.phases
    steps = np.abs(np.diff(np.array(record.q_des), axis=0)).max(axis=1)
    assert steps.max() < 2e-3, steps.max()  # [rad] per tick: the wave's own speed, no jump at the start


def test_a_start_refused_when_built_again_leaves_the_reference_at_rest_where_it_stopped(tmp_path, monkeypatch):
    """``start`` during a wave whose second build (on where the stop rests) fails, as a user's task may for another
    posture: the start is refused with the reason, the reference rests where the stop ended, without a jump, until
    the operator stops the run."""
    (tmp_path / "wave.toml").write_text(WAVE.replace("duration = 0.3", "duration = 2.0"))
    (tmp_path / "rest.toml").write_text(REST)
    channel, answers, builds = OperatorChannel(), {}, []
    build = TaskRunner.build

    def failing_second_build(self, task, q_start):
        if task.name == "rest":
            builds.append(q_start)
            if len(builds) == 2:
                raise InfeasibleTask('phase "rest": not feasible from this posture (test)')
        return build(self, task, q_start)

    monkeypatch.setattr(TaskRunner, "build", failing_second_build)

    def at(tick):
        if tick.t >= 0.12 and "start" not in answers:
            answers["start"] = threading.Thread(
                target=lambda: answers.setdefault("ok", channel.request("start", 30, task=str(tmp_path / "rest.toml"))))
            answers["start"].start()
        if "ok" in answers and "stop" not in answers:
            answers["stop"] = tick.t
        if "stop" in answers and tick.t >= answers["stop"] + 0.3 and "posted" not in answers:
            answers["posted"] = channel.post("stop")

    result, runner, record, _ = run(FileTask.load(str(tmp_path / "wave.toml")), operator=channel,
                                    hooks=[Record(at=at)])
    answers["start"].join(10)
    assert len(builds) == 2 and not answers["ok"].ok
    assert "not feasible from this posture" in answers["ok"].error
    assert "the reference rests where it stopped" in answers["ok"].error
    assert result.end == "stopped" and result.tripped is None and runner.task.name == "wave"
    i = record.phases.index("rest")
    assert "stop" in record.phases[:i]
    q = np.array(record.q_des)
    np.testing.assert_allclose(q[i:], np.broadcast_to(builds[1], q[i:].shape), atol=1e-9)  # at rest, there
    steps = np.abs(np.diff(q, axis=0)).max(axis=1)
    assert steps.max() < 2e-3, steps.max()  # [rad] per tick: no jump


class RobotOff(Counting):
    """Reports its servos cut (a robot-side trip) for robot times in [0.3, 0.4) s."""

    _frame_time = 0.0  # [s] robot time of the last frame read

    @property
    def robot_state(self):
        t = self._frame_time
        return "servo_off" if 0.3 <= t < 0.4 else super().robot_state

    def read(self, timeout=None):
        f = super().read(timeout)
        self._frame_time = float(f.time)
        return f


def test_after_a_trip_and_a_reset_the_operator_starts_a_task_that_drives_again(tmp_path):
    """A robot-side trip latches the hold; once the robot is back, a reset, then ``start``: the new task leaves the
    held posture and runs to its end (the reference is no longer the hold)."""
    (tmp_path / "wave.toml").write_text(WAVE)
    channel = OperatorChannel()
    answers = {}

    def ask(key, action, **args):
        answers[key] = None
        threading.Thread(target=lambda: answers.__setitem__(key, channel.request(action, 30, **args))).start()

    def at(tick):
        if float(tick.frame.time) >= 0.45 and "reset" not in answers:
            ask("reset", "reset")
        if answers.get("reset") is not None and answers["reset"].ok and "start" not in answers:
            ask("start", "start", task=str(tmp_path / "wave.toml"))

    backend = RobotOff(SimRobot(SimConfig.named("hanging", seed=0)))
    try:
        task = FileTask.load("hold").shortened(0.8, settle=SETTLE)
        runner = TaskRunner(task, backend.info)
        record = Record(runner, at=at)
        loop = ControlLoop(backend, runner.manager(), hooks=[runner, record], settle=task.settle)
        result = runner.run(loop, operator=channel, hold_timeout=2.0)  # a regression ends, not hangs
    finally:
        backend.close()
    assert result.trips == 1 and "robot_servo_off" in result.tripped and result.resets == 1
    assert answers["start"] is not None and answers["start"].ok, answers
    assert result.end == "completed" and record.phases[-1] == "wave"
    knee = backend.info.joint_index("RLEG_JOINT3")
    wave = np.array([q[knee] for q, ph in zip(record.q_des, record.phases, strict=True) if ph == "wave"])
    assert np.ptp(wave) > 0.02  # the wave drives the knee (+-0.05 rad): not the held posture


TWO_GAINS = """
name = "two_gains"
[settle]
duration = 0.15
[[phases]]
name = "stiff"
mode = "torque"
k6 = 1.0
duration = 0.2
[phases.reference]
type = "hold"
[[phases]]
name = "soft"
mode = "torque"
k6 = 0.5
duration = 0.2
[phases.reference]
type = "hold"
"""


def test_torque_phases_with_their_own_gains_run_and_the_command_stays_continuous(tmp_path):
    """K6 = 1 then K6 = 0.5: the second phase's gains are set in place at its start (ramped: no step in q_des at the
    boundary), the run ends completed, and the law runs the new K6 on every torque joint."""
    (tmp_path / "two.toml").write_text(TWO_GAINS)
    k6 = []
    probe = Record(at=lambda tick: k6.append(runner_box[0].manager().law.k6.copy()))
    runner_box = []
    backend = Counting(SimRobot(SimConfig.named("hanging", seed=0)))
    try:
        runner = TaskRunner(FileTask.load(str(tmp_path / "two.toml")), backend.info)
        runner_box.append(runner)
        record = Record(runner)
        loop = ControlLoop(backend, runner.manager(), hooks=[runner, record, probe], settle=0.15)
        result = runner.run(loop)
    finally:
        backend.close()
    assert result.end == "completed" and result.tripped is None
    mask = runner.manager().torque_mask
    phases = record.phases
    k = phases.index("soft")
    assert np.allclose(k6[k - 1][mask], 1.0) and np.allclose(k6[-1][mask], 0.5)
    assert set(record.modes[k - 5:]) == {"torque"}
    steps = np.abs(np.diff(np.array(record.q_des), axis=0)).max(axis=1)
    assert steps[k - 5:k + 100].max() < 2e-4, steps[k - 5:k + 100].max()  # [rad] per tick, across the boundary


@pytest.mark.slow
def test_the_force_task_file_reproduces_the_force_experiment():
    """config/tasks/force.toml, whole (1 s hold, 6 s of the sinusoid): the apex error of the measured force within
    5 % of the amplitude, as `servotau experiment force` (docs/results.md)."""
    from servotau.control.loop import estimator_config
    from servotau.experiments.common import Run, ft_offsets_hanging
    from servotau.experiments.force import force_metrics

    run_ = Run("force task")

    def at(tick):
        t = tick.t - 1.0  # from the force phase's start
        if t >= 0:
            run_.time.append(t)
            run_.f_ref.append(np.array(tick.terms.f_d[:3]))
            run_.f_hat.append(np.array(tick.terms.f_hat[:3]))

    offsets = ft_offsets_hanging(0, estimator_config())
    result, *_ = run(FileTask.load("force"), "force", lambda frames: offsets, hooks=[Record(at=at)])
    assert result.end == "completed" and result.tripped is None
    metrics = force_metrics(run_, "f_hat")
    print("force task metrics:", metrics)
    assert abs(metrics["apex_error_pct"]) < 5.0, metrics
