"""Fixtures shared by the test modules; helpers live in the ``support`` package (tests/support/).

Wall time in the multi-process fixtures is a safety net only: the tests assert robot-time behaviour
(ticks, seq, simulated time), and must pass on a loaded 2-core machine.
"""

from __future__ import annotations

import os

import pytest
from support.hal import endpoint, free_port, robot_server

CASE_READERS = {"test_workbench_effects"}  # modules reading tests/support/workbench_cases' outcomes
# The slowest files [s of a test worker, measured with --durations], run first: `make test` gives pytest-xdist whole
# files in collection order (--dist loadfile --no-loadscope-reorder), so the short files fill the end and the two
# workers finish together (they ended up to 20 s apart with a 13 s file last). A file not listed keeps its place.
SLOWEST_FIRST = ("test_workbench_effects.py", "test_identification_pipeline.py", "test_workbench_diagnose.py",
                 "test_apps_identify.py", "test_workbench_preprocess.py", "test_simrobot_sim.py",
                 "test_identification_deadband.py", "test_hal_processes.py", "test_experiments_plant_family.py",
                 "test_layers.py", "test_control_tasks_run.py", "test_apps_model.py", "test_apps_demo.py",
                 "test_workbench_data.py", "test_workbench_resolution.py", "test_actuator_effects_delay.py")
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
    """Put the slowest files first (:data:`SLOWEST_FIRST`). Start simulating the workbench's cases as the session
    starts, when a test reading them is selected: the suite's other tests keep one core busy, the cases' worker
    processes use the other one meanwhile. The slow cases are prefetched only when a slow test is selected
    (tests/support/workbench_cases). Under pytest-xdist (`make test` runs 2 workers, which keep both cores busy)
    every worker collects every test, so the cases start on the first test reading them instead, in that test's
    worker only."""
    from support import workbench_cases

    rank = {name: i for i, name in enumerate(SLOWEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the others keep their order
    workbench_cases.PREFETCH_SLOW = any(item.get_closest_marker("slow") for item in items)
    readers = (getattr(getattr(item, "module", None), "__name__", "") in CASE_READERS for item in items)
    if not config.option.collectonly and "PYTEST_XDIST_WORKER" not in os.environ and any(readers):
        workbench_cases.prefetch()
