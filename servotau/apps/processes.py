"""Child processes of the launchers, benchmarks and tests: free loopback ports, start, stop."""

from __future__ import annotations

import signal
import socket
import subprocess
import time
from pathlib import Path

from servotau.errors import HalError


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_ready(p: subprocess.Popen, ready_file: Path, timeout: float, what: str = "the robot process") -> None:
    """Wait until ``p`` touches ``ready_file``; :class:`HalError` if it exits first or after ``timeout`` [s]."""
    deadline = time.monotonic() + timeout
    while not Path(ready_file).exists():
        if p.poll() is not None:
            raise HalError(f"{what} exited with code {p.returncode} before serving")
        if time.monotonic() > deadline:
            raise HalError(f"{what} did not start serving within {timeout} s")
        time.sleep(0.01)


def stop_process(p: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int:
    """Stop ``p`` (``sig``, then SIGKILL after ``timeout`` [s]) and return its exit code."""
    if p.poll() is None:
        p.send_signal(sig)
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    return p.returncode
