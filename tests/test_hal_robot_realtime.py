"""hal/robot/realtime.py: SCHED_FIFO for a HAL process, validated, and never fatal when refused."""

from __future__ import annotations

import pytest

from servotau.hal.errors import HalError
from servotau.hal.robot import realtime


@pytest.mark.parametrize("bad", [-1, 100, 1.5, True, "50"])
def test_priority_outside_0_99_is_a_clear_error(bad):
    with pytest.raises(HalError, match=r"expected 0 \(ordinary scheduling\) or a SCHED_FIFO priority 1..99"):
        realtime.check_priority(bad)


def test_zero_leaves_the_scheduling_alone(monkeypatch):
    monkeypatch.setattr(realtime.os, "sched_setscheduler", lambda *_: pytest.fail("must not be called"))
    assert realtime.set_realtime_priority(0) is False


def test_refused_priority_warns_and_returns_false(monkeypatch, caplog):
    """Without root or CAP_SYS_NICE the process says so and runs with ordinary scheduling."""
    def refuse(*_):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(realtime.os, "sched_setscheduler", refuse)
    assert realtime.set_realtime_priority(50) is False
    assert "realtime_priority 50: SCHED_FIFO refused" in caplog.text


def test_granted_priority_is_requested_for_the_calling_thread(monkeypatch):
    calls = []
    monkeypatch.setattr(realtime.os, "sched_setscheduler", lambda pid, policy, param: calls.append(
        (pid, policy, param.sched_priority)))
    assert realtime.set_realtime_priority(50) is True
    assert calls == [(0, realtime.os.SCHED_FIFO, 50)]


def test_zenoh_backend_from_config_asks_for_its_priority_before_the_session_opens(tmp_path, monkeypatch):
    """[hal.zenoh] realtime_priority reaches set_realtime_priority, before zenoh's threads exist."""
    from support.hal import endpoint, free_port, robot_server

    from servotau.hal import open_backend
    from servotau.hal.backends import zenoh as zenoh_backend

    calls = []
    real_session = zenoh_backend.Session
    monkeypatch.setattr(zenoh_backend, "set_realtime_priority", lambda p: calls.append(("priority", p)))
    monkeypatch.setattr(zenoh_backend, "Session", lambda *a: calls.append(("session",)) or real_session(*a))
    port = free_port()
    cfg = tmp_path / "hal.toml"
    cfg.write_text(f'[hal]\nbackend = "zenoh"\n[hal.zenoh]\nrobot = "fake"\nconnect = ["{endpoint(port)}"]\n'
                   "realtime_priority = 50\n")
    with robot_server(tmp_path, port), open_backend(cfg) as b:
        assert b.read().seq >= 0
    assert calls[:2] == [("priority", 50), ("session",)]


def test_timer_slack_is_set_for_the_calling_thread():
    """The real-time robot loop sleeps with a 1 us timer slack instead of spinning (Linux)."""
    import threading

    result = {}

    def in_a_thread():  # the slack is per thread: leave the test runner's alone
        result["set"] = realtime.set_timer_slack(1000)
        result["read"] = realtime.timer_slack()

    t = threading.Thread(target=in_a_thread)
    t.start()
    t.join()
    if realtime.timer_slack() is None:
        pytest.skip("no prctl timer slack on this platform")
    assert result == {"set": True, "read": 1000}
