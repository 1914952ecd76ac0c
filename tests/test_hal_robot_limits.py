"""Robot-side velocity and acceleration limits of q_des (per joint, clamp or trip), in robot time."""

from __future__ import annotations

import numpy as np
import pytest

from servotau.config import Section
from servotau.errors import ConfigError, HalError
from servotau.hal import Firmware, FirmwareState, InProcessBackend, SafetyConfig
from servotau.hal.robot.limits import RateLimiter
from servotau.hal.wire.protocol import FLAG_HOLDING, FLAG_RATE_LIMITED
from servotau.simrobot.fake import FakeRobot

INFO = FakeRobot().info
DT = INFO.period


def creep(fw: Firmware, step: float = 0.09, ticks: int = 600, joint: int = 3) -> np.ndarray:
    """The issue's creeping command: ``q_des`` of one joint advances ``step`` [rad] per tick from the measured
    position (under the 0.1 rad position-error trip); the robot tracks the applied q_des perfectly. The applied
    q_des per tick (NaN rows: servos off)."""
    q = np.zeros(INFO.nq)
    out = []
    for k in range(ticks):
        cmd = q.copy()
        cmd[joint] = q[joint] + step
        fw.accept(cmd, k * DT)
        applied = fw.output(q, k * DT)
        out.append(np.full(INFO.nq, np.nan) if applied is None else applied)
        if applied is not None:
            q = applied.copy()
    return np.array(out)


def over_velocity(applied: np.ndarray, v_max: float) -> int:
    """Ticks whose applied q_des moved faster than ``v_max`` [rad/s] on some joint."""
    v = np.abs(np.diff(applied, axis=0)) / DT
    return int((np.nan_to_num(v) > v_max * (1 + 1e-9)).any(axis=1).sum())


def test_creeping_commands_are_clamped_to_the_velocity_and_acceleration_limits():
    """Commands creeping 0.09 rad per tick (90 rad/s): with limit_action = "clamp" none is applied above
    max_velocity or max_acceleration; the joint ramps at the limit, flagged RATE_LIMITED."""
    fw = Firmware(INFO, SafetyConfig(max_position_error=10.0))
    applied = creep(fw, ticks=200)  # 1 rad at 5 rad/s: within the joint limits (1.5 rad)
    assert over_velocity(applied, 5.0) == 0
    acc = np.abs(np.diff(applied, 2, axis=0)) / DT**2
    assert acc.max() <= 2000.0 * (1 + 1e-9)
    v = np.diff(applied[:, 3]) / DT
    assert v[-1] == pytest.approx(5.0)  # reached the limit and stays there
    assert fw.counters["rate_limited_ticks"] == 200 and fw.flags & FLAG_RATE_LIMITED
    assert fw.state == FirmwareState.RUNNING


def test_unlimited_firmware_applies_every_creeping_command():
    """A creep with limits out of the way: every tick moves at 10 rad/s (what the issue measured: every command
    applied)."""
    fw = Firmware(INFO, SafetyConfig(max_position_error=10.0, max_velocity=1e3, max_acceleration=1e9))
    assert over_velocity(creep(fw, step=0.01, ticks=100), 5.0) == 99


def test_creeping_commands_trip_to_a_hold():
    """limit_action = "trip": the first command beyond a limit holds the measured position; nothing above the
    limit is applied; a command within the limits resumes."""
    fw = Firmware(INFO, SafetyConfig(limit_action="trip"))
    applied = creep(fw, ticks=50)
    assert over_velocity(applied, 5.0) == 0
    assert fw.state == FirmwareState.HOLDING and fw.flags & FLAG_HOLDING
    assert fw.counters["rate_limit_trips"] >= 1 and "velocity/acceleration" in fw.status()["hold_reason"]
    np.testing.assert_array_equal(applied[-1], np.zeros(INFO.nq))  # never moved
    fw.accept(np.full(INFO.nq, 0.0005), 1.0)  # 0.5 rad/s from rest
    np.testing.assert_array_equal(fw.output(np.zeros(INFO.nq), 1.0), np.full(INFO.nq, 0.0005))
    assert fw.state == FirmwareState.RUNNING


def test_per_joint_limits_from_the_config():
    """[hal.safety.joints.<joint>] overrides one joint's limits; the others keep [hal.safety]'s."""
    s = SafetyConfig.from_section(Section({"max_velocity": 2.0, "joints": {"J03": {"max_velocity": 0.5}}},
                                          "hal.toml", "safety"))
    v, a = s.rate_limits(INFO)
    assert v[3] == 0.5 and v[0] == 2.0 and (a == 2000.0).all()
    fw = Firmware(INFO, s)
    assert over_velocity(creep(fw, ticks=200, joint=3), 0.5) == 0
    cmd = np.full(INFO.nq, 1.0)
    lim = RateLimiter(v, a, DT)
    lim.reset(np.zeros(INFO.nq))
    for _ in range(100):
        lim.applied(lim.bound(cmd))
    out = lim.bound(cmd)
    assert (out - lim._q)[3] == pytest.approx(0.5 * DT) and (out - lim._q)[0] == pytest.approx(2.0 * DT)


def test_rate_limits_reach_a_target_without_overshoot():
    """A far target is reached at the velocity limit, braking at the acceleration limit, without overshoot."""
    lim = RateLimiter(np.array([5.0]), np.array([2000.0]), DT)
    lim.reset(np.zeros(1))
    qs = []
    for _ in range(200):
        q = lim.bound(np.array([0.3]))
        lim.applied(q)
        qs.append(q[0])
    qs = np.array(qs)
    assert qs.max() <= 0.3 and qs[-1] == 0.3
    assert np.abs(np.diff(qs, 2)).max() / DT**2 <= 2000.0 * (1 + 1e-9)


def test_rate_limits_do_not_touch_a_normal_swing():
    """A 1 Hz, 0.3 rad swing of every joint (as tests/support/controller.py commands) is never bounded."""
    with InProcessBackend(FakeRobot()) as b:
        f0 = b.read()
        for k in range(2000):
            b.read()
            b.write_array(f0.q + 0.3 * np.sin(2 * np.pi * k * DT))
        assert b.status()["rate_limited_ticks"] == 0 and b.robot_state == "running"


def test_a_command_within_the_limits_passes_unchanged_at_any_speed_under_the_velocity_limit():
    """A 2.4 Hz, 0.3 rad sinusoid from rest (4.5 rad/s and 68 rad/s^2 at most, under 5 rad/s and 2000 rad/s^2) is
    applied as commanded: each tick's target is on its way, not a point to stop at."""
    lim = RateLimiter(np.array([5.0]), np.array([2000.0]), DT)
    lim.reset(np.zeros(1))
    for k in range(1, 1000):
        target = np.array([0.3 * (1.0 - np.cos(2 * np.pi * 2.4 * k * DT))])
        q = lim.bound(target)
        assert q[0] == target[0], k
        lim.applied(q)


def test_a_step_toward_the_measured_angle_is_free_and_the_limits_apply_beyond_it():
    """q_des 15 mrad ahead of a joint moving at 2 rad/s; a hold behind the joint: q_des jumps to the measured angle
    at once (no velocity or acceleration bound on that part), then moves beyond it from rest within the limits. A
    command moving away from the joint stays bounded as before, and a NaN reading frees nothing."""
    lim = RateLimiter(np.array([5.0]), np.array([2000.0]), DT)
    lim.reset(np.zeros(1))
    for k in range(1, 16):  # q_des moving at 2 rad/s
        lim.applied(lim.bound(np.array([0.002 * k])))
    q = np.array([0.015])  # the joint, 15 mrad behind q_des = 0.030
    out = lim.bound(np.array([0.0]), q)  # hold 15 mrad behind the joint
    assert out[0] <= q[0] and q[0] - out[0] <= 2000.0 * DT * DT + 1e-12  # at the joint, then from rest
    lim.applied(out)
    nxt = lim.bound(np.array([0.0]), q)
    assert 0 < out[0] - nxt[0] <= 2 * 2000.0 * DT * DT + 1e-12  # accelerating from rest
    away = lim.bound(np.array([0.5]), q)  # away from the joint: bounded
    assert away[0] - out[0] <= 5.0 * DT + 1e-12
    lim2 = RateLimiter(np.array([5.0]), np.array([2000.0]), DT)
    lim2.reset(np.array([0.03]))
    assert lim2.bound(np.array([0.0]), np.array([np.nan]))[0] >= 0.03 - 2000.0 * DT * DT - 1e-12


@pytest.mark.parametrize(("data", "match"), [
    ({"max_velocity": -1.0}, r"field 'safety.max_velocity' = -1.0: expected a finite number > 0 \[rad/s\]"),
    ({"max_acceleration": 0}, r"field 'safety.max_acceleration' = 0: expected a finite number > 0"),
    ({"limit_action": "explode"}, r"field 'safety.limit_action' = 'explode'"),
    ({"joints": {"J03": {"max_velocity": -2.0}}}, r"field 'safety.joints.J03.max_velocity' = -2.0"),
    ({"max_command_age_ticks": -1}, r"field 'safety.max_command_age_ticks' = -1"),
    ({"invalid_encoders_after": 0}, r"field 'safety.invalid_encoders_after' = 0"),
])
def test_bad_limits_are_refused_naming_the_field(data, match):
    with pytest.raises(ConfigError, match=match):
        SafetyConfig.from_section(Section(data, "hal.toml", "safety"))


def test_unknown_joint_in_the_limits_is_refused():
    s = SafetyConfig.from_section(Section({"joints": {"NOPE": {"max_velocity": 1.0}}}, "hal.toml", "safety"))
    with pytest.raises(HalError, match=r'safety.joints.NOPE: "NOPE" is not a joint of fake'):
        Firmware(INFO, s)


def test_an_unknown_joint_in_the_limits_is_a_one_line_error_before_serving(capsys):
    """python -m servotau.hal with [hal.safety.joints] naming no joint of the robot: exit 2 naming the field and
    the joints expected, no traceback, nothing served."""
    from support.hal import free_port

    from servotau.hal.robot.cli import main

    code = main(["--robot", "servotau.simrobot.fake:FakeRobot", "--listen", f"tcp/127.0.0.1:{free_port()}",
                 "--max-ticks", "1", "--safety", '{"joints": {"NOPE": {"max_velocity": 1.0}}}'])
    err = capsys.readouterr().err
    assert code == 2 and 'safety.joints.NOPE: "NOPE" is not a joint of fake: expected one of' in err, err
    assert "Traceback" not in err


def test_the_watchdog_options_fill_their_lock_step_twins_only_when_these_are_not_given():
    """--hold-after sets lockstep_hold_after too, unless --lockstep-hold-after or --safety gives it."""
    import argparse

    from servotau.hal.robot.cli import _safety_of

    def safety(hold_after=None, lockstep_hold_after=None, extra="{}"):
        return _safety_of(argparse.Namespace(hold_after=hold_after, servo_off_after=None, safety=extra,
                                             lockstep_hold_after=lockstep_hold_after, lockstep_servo_off_after=None))

    assert safety(hold_after=0.05).lockstep_hold_after == 0.05
    assert safety(hold_after=0.05, lockstep_hold_after=0.2).lockstep_hold_after == 0.2
    s = safety(hold_after=0.05, extra='{"lockstep_hold_after": 0.3}')
    assert (s.hold_after, s.lockstep_hold_after) == (0.05, 0.3)

