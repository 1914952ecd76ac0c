"""Fixtures shared by the test modules; helpers live in the ``support`` package (tests/support/).

Wall time in the multi-process fixtures is a safety net only: the tests assert robot-time behaviour
(ticks, seq, simulated time), and must pass on a loaded 2-core machine.
"""

from __future__ import annotations

import os

import pytest
from support.hal import endpoint, free_port, robot_server

CASE_READERS = {"test_workbench_effects"}  # modules reading tests/support/workbench_cases' outcomes
FRAME_TIMEOUT = 5.0  # [s] controller-side read timeout of the fixtures' backends: a safety net, not a test


@pytest.fixture
def fake_server(tmp_path):
    """A ``FakeRobot(seed=0)`` served in lock-step over Zenoh in a subprocess: its port (killed after the test)."""
    port = free_port()
    with robot_server(tmp_path, port):
        yield port


@pytest.fixture
def fake_zenoh(fake_server):
    """A :class:`~servotau.hal.ZenohBackend` connected to :func:`fake_server` (closed after the test)."""
    from servotau.hal import ZenohBackend

    with ZenohBackend("fake", connect=[endpoint(fake_server)], frame_timeout=FRAME_TIMEOUT) as b:
        yield b


@pytest.fixture(scope="session", autouse=True)
def _workbench_pool():
    """Shut the workbench cases' worker processes down at the end of the session (tests/support/workbench_cases)."""
    yield
    from support import workbench_cases

    for pool in workbench_cases.POOL:
        pool.shutdown(cancel_futures=True)


@pytest.hookimpl(trylast=True)  # after `-m` has deselected
def pytest_collection_modifyitems(config, items):
    """Start simulating the workbench's cases as the session starts, when a test reading them is selected: the
    suite's other tests keep one core busy, the cases' worker processes use the other one meanwhile. The slow
    cases are prefetched only when a slow test is selected (tests/support/workbench_cases). Under pytest-xdist
    (`make test` runs 2 workers, which keep both cores busy) every worker collects every test, so the cases start
    on the first test reading them instead, in that test's worker only."""
    from support import workbench_cases

    workbench_cases.PREFETCH_SLOW = any(item.get_closest_marker("slow") for item in items)
    readers = (getattr(getattr(item, "module", None), "__name__", "") in CASE_READERS for item in items)
    if not config.option.collectonly and "PYTEST_XDIST_WORKER" not in os.environ and any(readers):
        workbench_cases.prefetch()
