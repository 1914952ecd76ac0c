"""servotau.apps.processes: readiness of a child process and a stop that always ends it."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

from servotau.apps.processes import free_port, stop_process, wait_ready
from servotau.errors import HalError


def test_wait_ready_reports_a_child_that_exits_before_serving(tmp_path):
    p = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
    with pytest.raises(HalError, match="the robot process exited with code 3 before serving"):
        wait_ready(p, tmp_path / "never", timeout=30.0)


def test_wait_ready_times_out_and_returns_once_the_file_exists(tmp_path):
    p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        with pytest.raises(HalError, match="did not start serving within 0.2 s"):
            wait_ready(p, tmp_path / "never", timeout=0.2)
        (tmp_path / "ready").touch()
        wait_ready(p, tmp_path / "ready", timeout=0.2)
    finally:
        assert stop_process(p) == -signal.SIGTERM


def test_stop_process_kills_a_child_that_ignores_sigterm():
    code = ("import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); print(1, flush=True); "
            "time.sleep(60)")
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE)
    p.stdout.readline()  # the handler is installed
    assert stop_process(p, timeout=0.2) == -signal.SIGKILL


def test_free_port_is_bindable():
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", free_port()))
