"""Tests of the control loop (control/loop.py) on the in-process simulated robot: the phases, the hooks, a trip."""

import numpy as np
import pytest

from servotau.control.loop import SETTLE, ControlLoop, LoopHook, Tick
from servotau.control.trajectory import TrajectoryPoint
from servotau.hal.backends.inprocess import InProcessBackend
from servotau.simrobot.sim import SimConfig, SimRobot

SETTLE_S = 0.1  # [s] 100 ticks: more than the estimator's 80-sample windows, so the calibration has estimates


@pytest.fixture
def backend():
    b = InProcessBackend(SimRobot(SimConfig.named("hanging")))
    yield b
    b.close()


class Spy(LoopHook):
    """Records every hook call as (method, k) and what the tick held at that moment."""

    def __init__(self, wants_truth=False):
        self.wants_truth = wants_truth
        self.calls = []
        self.truths = []

    def settled(self, tick: Tick) -> None:
        self.calls.append(("settled", tick.k))

    def before_control(self, tick: Tick) -> None:
        assert tick.terms is None and tick.reference is not None
        self.calls.append(("before_control", tick.k))

    def on_tick(self, tick: Tick) -> None:
        assert tick.terms is not None
        self.calls.append(("on_tick", tick.k))
        self.truths.append(tick.truth)


def test_settle_default_is_half_a_second(backend):
    """The default settle phase is SETTLE = 0.5 s of ticks."""
    assert SETTLE == 0.5
    assert ControlLoop(backend).settle_ticks == 500


def test_ft_offsets_are_calibrated_on_the_last_settle_tick_from_the_frames_before_it(backend):
    """The F/T offsets are computed once, on the last settle tick, from the frames of the settle ticks before it,
    and set in the estimator before that tick's estimate."""
    seen = []
    offsets = np.full((4, 6), 0.25)

    def calibrate(frames):
        seen.append([f.seq for f in frames])
        return offsets

    class Offsets(LoopHook):
        def before_control(self, tick):
            seen.append((tick.k, bool(np.all(loop.estimator.ft_offsets == offsets))))

    loop = ControlLoop(backend, settle=SETTLE_S, ft_offsets=calibrate, hooks=[Offsets()])
    first = loop.start().seq
    loop.run(None, 0.01)
    n = loop.settle_ticks
    assert n == 100
    calls = [s for s in seen if isinstance(s, list)]
    assert calls == [list(range(first, first + n - 1))]  # ticks 0 .. n - 2
    with_offsets = {k: ok for k, ok in (s for s in seen if isinstance(s, tuple))}
    assert not with_offsets[n - 2] and with_offsets[n - 1] and with_offsets[n]


def test_default_calibration_gives_finite_offsets(backend):
    """Without ``ft_offsets`` the loop calibrates on the settle frames (feet free): finite offsets are set."""
    loop = ControlLoop(backend, settle=SETTLE_S)
    loop.run(None, 0.005)
    assert np.all(np.isfinite(loop.estimator.ft_offsets)) and np.any(loop.estimator.ft_offsets != 0.0)


def test_hooks_are_called_once_per_tick_in_order(backend):
    """settled once on the first tick after the settle phase, before_control then on_tick once per tick; ground
    truth only when a hook wants it."""
    plain, truthful = Spy(), Spy(wants_truth=True)
    loop = ControlLoop(backend, settle=SETTLE_S, hooks=[plain, truthful])
    result = loop.run(None, 0.02)
    n, total = loop.settle_ticks, loop.settle_ticks + 20
    assert result.ticks == total and result.tripped is None
    assert result.sim_seconds == pytest.approx(total * backend.info.period)
    expected = []
    for k in range(total):
        expected += [("settled", k)] * (k == n) + [("before_control", k), ("on_tick", k)]
    assert plain.calls == expected and truthful.calls == expected
    assert all(t is not None for t in truthful.truths[1:])  # the in-process backend keeps truth once asked


def test_ground_truth_is_read_only_for_a_hook_that_wants_it(backend):
    """Without a hook that ``wants_truth`` the loop never asks the backend for ground truth."""
    plain = Spy()
    ControlLoop(backend, settle=SETTLE_S, hooks=[plain]).run(None, 0.005)
    assert plain.truths and all(t is None for t in plain.truths)


def test_reference_follows_the_settle_phase_and_the_mode_switches(backend):
    """While settling the loop holds the start posture in position mode; then it requests the run's mode and the
    reference callable gets t = (k - settle_ticks) * period."""
    refs, modes = [], []

    class Modes(LoopHook):
        def on_tick(self, tick):
            refs.append((tick.k, tick.t, tick.reference))
            modes.append(tick.terms.mode)

    def reference(tick):
        return TrajectoryPoint(loop.hold.q + 1e-4 * tick.t, loop.hold.dq, loop.hold.ddq)

    loop = ControlLoop(backend, mode="torque", settle=SETTLE_S, hooks=[Modes()])
    q_start = loop.start().q.copy()
    loop.run(reference, 0.02)
    n, dt = loop.settle_ticks, backend.info.period
    for k, t, ref in refs:
        assert t == (k - n) * dt
        if k < n:
            assert ref is loop.hold
        else:
            np.testing.assert_allclose(ref.q, q_start + 1e-4 * t)
    assert set(modes[:n]) == {"position"} and set(modes[n:]) == {"torque"}


def test_a_safety_trip_stops_the_loop_after_writing_the_hold(backend):
    """A reference 0.2 rad away trips the command check: the loop writes the hold (the measured angles) on that
    tick, calls the hooks for it and stops; the result carries the report's message."""
    spy = Spy()
    jump_at = 5

    def reference(tick):
        q = loop.hold.q.copy()
        if tick.t >= jump_at * backend.info.period:
            q[backend.info.joint_names.index("RLEG_JOINT3")] += 0.2
        return TrajectoryPoint(q, loop.hold.dq, loop.hold.ddq)

    loop = ControlLoop(backend, settle=SETTLE_S, hooks=[spy])
    result = loop.run(reference, 1.0)
    n = loop.settle_ticks
    assert result.ticks == n + jump_at + 1
    assert "command_error" in result.tripped and "RLEG_JOINT3" in result.tripped
    assert spy.calls[-1] == ("on_tick", n + jump_at)
    assert loop.manager.terms.mode == "hold"
    np.testing.assert_allclose(backend.q_des, loop.manager.terms.q_des)


def test_the_loop_times_its_estimate_and_control_tick(backend):
    """Every tick carries the wall time of estimator.update and manager.tick [ns]."""
    times = []

    class Times(LoopHook):
        def on_tick(self, tick):
            times.append((tick.estimation_ns, tick.control_ns))

    ControlLoop(backend, settle=SETTLE_S, hooks=[Times()]).run(None, 0.005)
    assert all(e > 0 and c > 0 for e, c in times)


class Script(LoopHook):
    """An operator acting at given loop ticks through the channel (the hook sets the tick before the loop takes)."""

    def __init__(self, script):
        from servotau.control.operator import OperatorChannel, _Pending

        outer = self

        class Channel(OperatorChannel):
            def take(self):
                action = outer.script.pop(outer.k, None)
                return _Pending(action) if action is not None else None

            def answer(self, pending, ok, state, error=None):
                super().answer(pending, ok, state, error)
                outer.answers.append((outer.k, pending.action, pending.answer))

        self.script, self.answers, self.k = dict(script), [], 0
        self.channel = Channel()

    def on_tick(self, tick):
        self.k = tick.k


def test_a_reference_that_ends_ends_the_run(backend):
    """``reference(tick)`` returning None (a task's end) ends the run, ``completed``, without writing for that tick."""
    loop = ControlLoop(backend, settle=SETTLE_S)
    result = loop.run(lambda tick: loop.hold if tick.t < 0.01 - 1e-9 else None, None)
    assert result.end == "completed" and result.ticks == loop.settle_ticks + 10 + 1 and backend.robot.seq == 110


def test_while_tripped_a_mode_switch_is_refused_and_a_stop_ends_the_run(backend):
    """After a trip (hold until the operator): ``torque`` is refused with the reason, ``stop`` ends the run at once,
    ``stopped``, and the channel is closed."""
    n = int(round(SETTLE_S / backend.info.period))
    script = Script({n + 10: "torque", n + 20: "stop"})

    def reference(tick):
        q = loop.hold.q.copy()
        if tick.t >= 0.005:
            q[backend.info.joint_names.index("RLEG_JOINT3")] += 0.2
        return TrajectoryPoint(q, loop.hold.dq, loop.hold.ddq)

    loop = ControlLoop(backend, settle=SETTLE_S, hooks=[script])
    result = loop.run(reference, None, operator=script.channel, hold_timeout=None)
    (k1, a1, torque), (k2, a2, stop) = script.answers
    assert (k1, a1, k2, a2) == (n + 10, "torque", n + 20, "stop")
    assert not torque.ok and "cannot switch to torque mode: safety trip [command_error] RLEG_JOINT3" in torque.error
    assert stop.ok and stop.state == "stopped" and result.end == "stopped" and result.ticks == n + 21
    assert script.channel.closed


def test_a_stop_requested_while_settling_keeps_a_torque_loop_in_position_mode(backend):
    """A torque-mode loop stopped during its settle phase never switches to torque: it stops in position mode."""
    modes = []

    class Stop(LoopHook):
        def on_tick(self, tick):
            modes.append(tick.terms.mode)
            if tick.k == 50:  # settling (100 ticks)
                loop.request_stop()

    loop = ControlLoop(backend, mode="torque", settle=SETTLE_S, hooks=[Stop()])
    result = loop.run(lambda tick: loop.hold, None)
    assert result.end == "stopped" and result.tripped is None
    assert len(modes) > loop.settle_ticks and set(modes) == {"position"}
