"""A safety trip keeps the control loop alive: a latched hold that answers every frame until the operator acts;
skipped frames are a counted gap, not a trip. In-process simulated robot, robot time only."""

from __future__ import annotations

import dataclasses
import threading

import numpy as np
import pytest

from servotau.control.loop import ControlLoop, LoopHook
from servotau.control.manager import ControlManager
from servotau.control.operator import OperatorChannel
from servotau.control.terms import TORQUE_COMPONENTS
from servotau.hal.backends.inprocess import InProcessBackend
from servotau.simrobot.sim import SimConfig, SimRobot

SETTLE_S = 0.1  # [s] 100 ticks: more than the estimator's 80-sample windows
KNEE = "RLEG_JOINT3"


class Faulty:
    """An in-process backend whose frames get NaN knee encoders in [nan_from, nan_until) (robot ticks from the
    first frame) and that skips ``skip[tick]`` frames after the frame of robot tick ``tick`` (a late controller)."""

    def __init__(self, nan_from=None, nan_until=None, skip=None, servo_off=()):
        self.inner = InProcessBackend(SimRobot(SimConfig.named("hanging")))
        self.servo_off = range(0) if not servo_off else range(*servo_off)
        self._last_seq = None
        self.info = self.inner.info
        self.nan = (nan_from, nan_until)
        self.skip = dict(skip or {})
        self.seq0 = None
        self.reads = self.writes = 0

    def read(self, timeout=None):
        f = self.inner.read()
        if self.seq0 is None:
            self.seq0 = f.seq
        for _ in range(self.skip.pop(f.seq - self.seq0 - 1, 0)):  # the frames after the last one answered
            f = self.inner.read()
        self.reads += 1
        self._last_seq = f.seq
        i = f.seq - self.seq0
        if self.nan[0] is not None and self.nan[0] <= i < self.nan[1]:
            q = f.q.copy()
            q[self.info.joint_names.index(KNEE)] = np.nan
            f = dataclasses.replace(f, q=q)
        return f

    def write(self, q_des):
        self.writes += 1
        self.inner.write(q_des)

    def set_hold(self, on):
        self.inner.set_hold(on)

    @property
    def robot_state(self):
        """``servo_off`` for the robot ticks in ``servo_off`` (a robot-side trip), else the robot's own."""
        i = self._last_seq - self.seq0 if self.seq0 is not None else -1
        return "servo_off" if i in self.servo_off else self.inner.robot_state

    def ground_truth(self):
        return self.inner.ground_truth()

    def close(self):
        self.inner.close()


class ScriptedOperator(OperatorChannel):
    """An operator acting at given robot ticks (from the first frame) through the loop's channel; keeps answers."""

    def __init__(self, script):
        super().__init__()
        self.script = dict(script)  # robot tick -> action
        self.answers = []  # (tick, action, OperatorAnswer)
        self.tick = 0

    def take(self):
        action = self.script.pop(self.tick, None)
        if action is not None:
            pending = super().take() if self._pending else None
            assert pending is None
            self.post(action)
            return super().take()
        return None

    def answer(self, pending, ok, state, error=None):
        super().answer(pending, ok, state, error)
        self.answers.append((self.tick, pending.action, pending.answer))


class Recorder(LoopHook):
    wants_truth = True

    def __init__(self, backend, operator=None):
        self.backend, self.operator = backend, operator
        self.rows = []  # (robot tick, mode, q_des, truth q, torque terms all zero, integrals)
        self.trips = []
        self.hold_flags = []  # (robot tick, the robot's firmware holding on the controller's COMMAND_HOLD)

    def on_tick(self, tick):
        i = tick.frame.seq - self.backend.seq0
        if self.operator is not None:
            self.operator.tick = i
        t = tick.terms
        zero = all(not np.any(getattr(t, c)) for c in TORQUE_COMPONENTS)
        law = self.loop.manager.law
        q_true = tick.truth.q.copy() if tick.truth is not None else np.full(len(t.q_des), np.nan)
        self.rows.append((i, t.mode, t.q_des.copy(), q_true, zero,
                          law.torque.integral.copy(), law.position_integral.i_q.copy()))
        self.hold_flags.append((i, self.backend.inner.firmware.hold_commanded))  # the robot holds on COMMAND_HOLD

    def tripped(self, tick, report):
        self.trips.append((tick.frame.seq - self.backend.seq0, report.check, report.where))


def _run(backend, operator=None, hold_timeout=None, duration=0.3, mode="torque", manager=None):
    rec = Recorder(backend, operator)
    loop = ControlLoop(backend, manager, mode=mode, settle=SETTLE_S, hooks=[rec])
    rec.loop = loop
    try:
        result = loop.run(None, duration, operator=operator, hold_timeout=hold_timeout)
    finally:
        backend.close()
    return loop, rec, result


def test_a_trip_latches_a_hold_that_answers_every_frame_until_reset_and_release():
    """NaN knee encoders in torque mode: the trip is reported once (check, joint); the loop holds the last valid
    measured posture with no torque terms and frozen integrals and answers every frame past the run's duration;
    a reset while the NaN lasts is refused with the reason; after it, accepted: position control at the held
    posture; the release ends the loop."""
    nan_from, nan_until = 150, 250  # robot ticks (the settle phase ends at 100)
    backend = Faulty(nan_from, nan_until)
    op = ScriptedOperator({200: "reset", 300: "status", 400: "reset", 450: "reset", 600: "release"})
    loop, rec, result = _run(backend, op, hold_timeout=None, duration=0.2)  # the run alone would end at 300
    assert rec.trips == [(nan_from, "invalid_frame", KNEE)]
    assert (result.end, result.trips, result.resets) == ("released", 1, 1)
    assert "invalid_frame" in result.tripped and KNEE in result.tripped
    assert backend.writes == backend.reads == result.ticks and result.robot_ticks == 601  # every frame answered
    answers = {(t, a): ans for t, a, ans in op.answers}
    refused = answers[(200, "reset")]
    assert not refused.ok and refused.state == "tripped" and "invalid_frame" in refused.error and KNEE in refused.error
    assert answers[(400, "reset")].ok and answers[(400, "reset")].state == "holding"
    assert answers[(450, "reset")].ok  # nothing latched any more: nothing to do
    assert answers[(600, "release")].ok and answers[(600, "release")].state == "released"
    assert op.closed and op.request("reset").ok is False  # the loop has ended: refused, not pending
    rows = {r[0]: r for r in rec.rows}
    q_hold = loop.manager.hold_posture
    q_valid = rows[nan_from - 1][2]  # the last command before the trip, near the last valid reading
    assert np.all(np.isfinite(q_hold)) and np.abs(q_hold - q_valid).max() < 0.01
    integrals = rows[nan_from][5:]
    brake = round(loop.manager.config.safety.hold_brake_time / backend.info.period)  # ticks the hold brakes
    knee = backend.info.joint_index(KNEE)
    for i in range(nan_from, 400):
        _, mode, q_des, q_true, zero, *ints = rows[i]
        assert mode == "hold" and zero
        if i >= nan_from + brake:
            np.testing.assert_array_equal(q_des, q_hold)
        else:  # the braking term of a robot at rest: under 1 mrad, none on a joint without finite readings
            assert np.abs(q_des - q_hold).max() < 1e-3
            assert q_des[knee] == q_hold[knee] or i >= nan_until
        for a, b in zip(ints, integrals, strict=True):
            np.testing.assert_array_equal(a, b)  # frozen
        assert np.abs(q_true - q_hold).max() < 0.005, i  # the robot holds the posture [rad]
    for i in range(401, 601):
        _, mode, q_des, q_true, zero, *_ = rows[i]
        assert mode == "position" and zero
        np.testing.assert_allclose(q_des, q_hold, atol=1e-12)  # position control at the held posture
        assert np.abs(q_true - q_hold).max() < 0.005, i
    assert loop.manager.mode.value == "position" and not loop.manager.tripped
    flags = dict(rec.hold_flags)  # the robot holds on the loop's COMMAND_HOLD from the trip to the reset
    assert not any(flags[i] for i in range(nan_from))
    assert all(flags[i] for i in range(nan_from + 1, 401)) and not any(flags[i] for i in range(402, 601))


def test_hold_timeout_releases_by_itself_after_that_much_robot_time():
    """Without an operator, the hold lasts hold_timeout [s] of robot time after the trip, then the loop ends."""
    backend = Faulty(150, 10_000)
    _, rec, result = _run(backend, None, hold_timeout=0.12)
    assert rec.trips == [(150, "invalid_frame", KNEE)]
    assert result.end == "hold_timeout" and result.robot_ticks == 150 + 120 + 1
    assert {r[1] for r in rec.rows if r[0] >= 150} == {"hold"}


def test_skipped_frames_in_torque_mode_are_counted_gaps_not_a_trip():
    """A late controller skips frames, also at the switch to torque mode: the estimate stays valid, the run
    completes in robot time and counts the gaps. After a gap longer than max_gap torque mode falls back to position
    control until the estimate is valid again (one window), then resumes; with gap_fallback = "trip" the gap trips
    a clear estimate_gap check instead."""
    skips = {99: 3, 140: 5, 200: 19}  # the first: the settle phase ends (tick 100) in the gap
    backend = Faulty(skip=skips)
    _, rec, result = _run(backend, None, duration=0.2)
    assert result.tripped is None and result.end == "completed"
    assert (result.gaps, result.missing_frames, result.longest_gap) == (3, 27, 19)
    assert result.robot_ticks == 300 and result.ticks == 300 - 27
    assert {r[1] for r in rec.rows if r[0] > 100} == {"torque"}
    backend = Faulty(skip={150: 30})
    loop, rec, result = _run(backend, None, duration=0.3)
    assert result.tripped is None and result.end == "completed" and loop.manager.gap_fallbacks == 1
    modes = {r[0]: r[1] for r in rec.rows}
    assert all(modes[i] == "torque" for i in range(101, 151))
    assert all(modes[i] == "position" for i in range(181, 261)) and modes[261] == "torque"
    assert all(modes[i] == "torque" for i in range(261, 400))
    steps = np.abs(np.diff(np.array([r[2] for r in rec.rows if r[0] > 100]), axis=0)).max()
    assert steps < 2e-3  # [rad] per tick: bumpless both ways (no jump of q_des)
    backend = Faulty(skip={150: 30})
    mgr = ControlManager.from_toml(backend.info)
    mgr = ControlManager(backend.info, dataclasses.replace(mgr.config, gap_fallback="trip"))
    _, rec, result = _run(backend, None, hold_timeout=0.0, duration=0.2, manager=mgr)
    assert rec.trips == [(181, "estimate_gap", "")] and "invalid for 80 more ticks" in result.tripped


def test_a_robot_side_trip_latches_the_controllers_hold_until_the_robot_is_back():
    """The robot reports its servos cut from tick 150 to 300 (a robot-side trip): the controller latches the
    robot_servo_off hold at once; a reset while the robot is off is refused, naming the robot-side reset; once the
    robot is back, the reset is accepted."""
    backend = Faulty(servo_off=(150, 300))
    op = ScriptedOperator({200: "reset", 350: "reset", 400: "release"})
    _, rec, result = _run(backend, op, hold_timeout=None, duration=0.2)
    assert rec.trips == [(150, "robot_servo_off", "robot")]
    answers = {(t, a): ans for t, a, ans in op.answers}
    refused = answers[(200, "reset")]
    assert not refused.ok and "ctl reset --robot-side" in refused.error, refused
    assert answers[(350, "reset")].ok and result.end == "released" and result.resets == 1


def test_operator_channel_across_threads():
    """request() waits for the loop thread to apply an action; an action the loop does not take in time is
    withdrawn (never applied later); malformed requests are refused naming the field; status needs no loop."""
    ch = OperatorChannel()
    ch.publish("tripped", "safety trip [x]")
    assert ch.request("status").state == "tripped" and ch.request("status").report == "safety trip [x]"
    late = ch.request("reset", timeout=0.05)
    assert not late.ok and "did not take 'reset'" in late.error and ch.take() is None
    assert "action = 'jump'" in ch.handle(b'{"action": "jump"}').error
    assert "not JSON" in ch.handle(b"{").error
    stop = threading.Event()

    def loop():
        while not stop.is_set():
            p = ch.take()
            if p is not None:
                ch.answer(p, p.action == "release", "released" if p.action == "release" else "tripped",
                          None if p.action == "release" else "still tripped")
            stop.wait(0.001)

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    try:
        no = ch.handle(b'{"action": "reset"}', timeout=10.0)
        yes = ch.handle(b'{"action": "release"}', timeout=10.0)
    finally:
        stop.set()
        t.join(5.0)
    assert (no.ok, no.error) == (False, "still tripped") and (yes.ok, yes.state) == (True, "released")
    ch.close("released")
    assert "has ended" in ch.request("release").error


@pytest.mark.parametrize("bad", [-1.0, float("nan")])
def test_bad_hold_timeout_is_a_clear_error(bad):
    from servotau.apps.control import main
    from servotau.cli import build_parser
    from servotau.errors import ControlError

    args = build_parser("control").parse_args(["control", "--backend", "inprocess", "--hold-timeout", str(bad)])
    with pytest.raises(ControlError, match="--hold-timeout"):
        main(args)
