"""Tests of the controller a user starts: servotau control (in process)."""

from servotau.apps.control import run_session
from servotau.hal.registry import open_backend

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
