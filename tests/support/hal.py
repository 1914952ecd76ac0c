"""Helpers of the HAL tests: free ports, robot-server and controller subprocesses (always cleaned up)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from servotau.apps.processes import free_port, stop_process, wait_ready
from servotau.errors import HalError

__all__ = ["ENV", "controller", "endpoint", "free_port", "query_status", "robot_server", "robot_status", "stop_process",
           "wait_until"]

SUPPORT = Path(__file__).resolve().parent
TESTS = SUPPORT.parent
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]))


def _die_with_parent() -> None:  # pragma: no cover - runs in the child
    """Linux: the child gets SIGTERM if the test process dies (no orphan robot servers)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def endpoint(port: int) -> str:
    return f"tcp/127.0.0.1:{port}"


@contextmanager
def robot_server(tmp: Path, port: int, *, seed: int = 0, clock: str = "lockstep", log: Path | None = None,
                 max_ticks: int | None = None, hold_after: float | None = None,
                 servo_off_after: float | None = None,
                 lockstep_hold_after: float = 1.0, lockstep_servo_off_after: float | None = None,
                 safety: dict | None = None, robot_kwargs: dict | None = None, timeout: float = 20.0):
    """A FakeRobot served over Zenoh in a subprocess; killed on exit whatever happens.

    The lock-step watchdog holds after 1 s of wall time unless given (shipped: 50 ms, SafetyConfig): a
    controller descheduled for 50 ms on a loaded machine would make the robot hold in the middle of a
    lock-step run, and the tests of determinism assert there is none. ``safety``: more [hal.safety]
    settings (``--safety``); ``robot_kwargs``: more FakeRobot arguments (e.g. ``encoder_faults``)."""
    ready = tmp / f"ready-{port}"
    args = [sys.executable, "-m", "servotau.hal", "--robot", "servotau.simrobot.fake:FakeRobot",
            "--kwargs", json.dumps({"seed": seed, **(robot_kwargs or {})}), "--listen", endpoint(port),
            "--clock", clock, "--ready-file", str(ready)]
    if log is not None:
        args += ["--log", str(log)]
    if max_ticks is not None:
        args += ["--max-ticks", str(max_ticks)]
    if hold_after is not None:
        args += ["--hold-after", str(hold_after)]
    if servo_off_after is not None:
        args += ["--servo-off-after", str(servo_off_after)]
    args += ["--lockstep-hold-after", str(lockstep_hold_after)]
    if lockstep_servo_off_after is not None:
        args += ["--lockstep-servo-off-after", str(lockstep_servo_off_after)]
    if safety:
        args += ["--safety", json.dumps(safety)]
    out = open(tmp / f"server-{port}.log", "w")
    p = subprocess.Popen(args, env=ENV, stdout=out, stderr=subprocess.STDOUT, preexec_fn=_die_with_parent)
    try:
        try:
            wait_ready(p, ready, timeout, "robot server")
        except HalError as exc:
            raise HalError(f"{exc}: {(tmp / f'server-{port}.log').read_text()}") from None
        yield p
    finally:
        stop_process(p)
        out.close()


def controller(port: int, *args: str) -> subprocess.Popen:
    """tests/support/controller.py in a subprocess (stdout and stderr piped)."""
    return subprocess.Popen([sys.executable, str(SUPPORT / "controller.py"), "--connect", endpoint(port), *args],
                            env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_die_with_parent)


def wait_until(predicate, timeout: float) -> None:
    """Poll ``predicate`` every 10 ms until it holds, for at most ``timeout`` [s] of wall time (a safety net: the
    caller's assertions say what had to happen)."""
    deadline = time.monotonic() + timeout
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.01)


def query_status(session, robot: str = "fake", timeout: float = 10.0) -> dict | None:
    """One answer of the robot's ``.../status`` queryable on the zenoh ``session`` (a
    :class:`~servotau.hal.wire.session.Session`), or None when none came within ``timeout`` [s] (a loaded robot
    answers after the commands queued before the query)."""
    from servotau.hal import keys

    for reply in session.z.get(keys(robot).status, timeout=timeout):
        if reply.ok is not None:
            return json.loads(reply.ok.payload.to_bytes())
    return None


def robot_status(port: int, until, *, robot: str = "fake", timeout: float = 30.0) -> dict | None:
    """The robot's ``.../status`` once ``until(status)`` holds, polled every 20 ms; ``timeout`` [s] of wall time
    is a safety net only (then the last status is returned, for the caller's assertion to show)."""
    from servotau.hal.wire.session import Session, zenoh_config

    s = Session(zenoh_config(connect=[endpoint(port)]))
    try:
        deadline = time.monotonic() + timeout
        while True:
            st = query_status(s, robot)
            if (st is not None and until(st)) or time.monotonic() > deadline:
                return st
            time.sleep(0.02)
    finally:
        s.close()
