"""hal/realtime.py: SCHED_FIFO for a HAL process, validated, and never fatal when refused."""

from __future__ import annotations

import pytest

from servotau.hal import realtime
from servotau.hal.errors import HalError


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
