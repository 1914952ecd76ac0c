"""Zenoh sessions: loopback config, validation, and the GIL switch interval they set."""

from __future__ import annotations

import sys

import pytest
from support.hal import endpoint, free_port

from servotau.hal.errors import HalError
from servotau.hal.wire.session import GIL_SWITCH_INTERVAL, Session, zenoh_config


def test_config_needs_an_endpoint_and_a_known_mode():
    with pytest.raises(HalError, match="expected at least one listen or connect endpoint"):
        zenoh_config()
    with pytest.raises(HalError, match="expected 'peer', 'client' or 'router'"):
        zenoh_config(listen=[endpoint(free_port())], mode="server")


def test_opening_a_session_lowers_the_gil_switch_interval_and_keeps_a_lower_one():
    """Zenoh's callback thread must get the GIL within a fraction of a 1 ms tick (CPython's default: 5 ms)."""
    old = sys.getswitchinterval()
    try:
        sys.setswitchinterval(0.005)
        s = Session(zenoh_config(listen=[endpoint(free_port())]))
        s.close()
        assert sys.getswitchinterval() == pytest.approx(GIL_SWITCH_INTERVAL)
        sys.setswitchinterval(GIL_SWITCH_INTERVAL / 2)
        s = Session(zenoh_config(listen=[endpoint(free_port())]))
        s.close()
        assert sys.getswitchinterval() == pytest.approx(GIL_SWITCH_INTERVAL / 2)
    finally:
        sys.setswitchinterval(old)


_THREADS_OF_A_LINK = """
import os, sys, time
from servotau.hal.wire.session import Session, zenoh_config
port = int(sys.argv[1])
a = Session(zenoh_config(listen=[f"tcp/127.0.0.1:{port}"]))
b = Session(zenoh_config(connect=[f"tcp/127.0.0.1:{port}"]))
sub = b.z.declare_subscriber("t/x")
pub = a.z.declare_publisher("t/x")
deadline = time.monotonic() + 10
while sub.try_recv() is None and time.monotonic() < deadline:
    pub.put(b"1")
    time.sleep(0.01)
print(" ".join(sorted(open(f"/proc/self/task/{t}/comm").read().strip() for t in os.listdir("/proc/self/task"))))
a.close()
b.close()
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="thread names from /proc")
@pytest.mark.parametrize("user_layout", [None, "(rx: (worker_threads: 1))"])
def test_zenoh_threads_follow_the_hal_layout_unless_the_user_sets_one(user_layout):
    """A HAL process runs zenoh's receive/accept/network work on its one app worker; ZENOH_RUNTIME overrides."""
    import os
    import subprocess

    env = {k: v for k, v in os.environ.items() if k != "ZENOH_RUNTIME"}
    if user_layout:
        env["ZENOH_RUNTIME"] = user_layout
    out = subprocess.run([sys.executable, "-c", _THREADS_OF_A_LINK, str(free_port())], env=env, capture_output=True,
                         text=True, timeout=60)
    threads = out.stdout.split()
    assert out.returncode == 0 and threads, out.stderr
    prefixes = {name.split("-")[0] for name in threads if "-" in name}
    if user_layout:
        assert "rx" in prefixes  # the user's layout keeps a receive pool
    else:
        assert prefixes <= {"app", "tx"} and "app" in prefixes, threads
