"""Zenoh sessions: loopback config, validation, and the GIL switch interval they set."""

from __future__ import annotations

import sys

import pytest
from hal_support import endpoint, free_port

from servotau.hal.errors import HalError
from servotau.hal.zenoh_session import GIL_SWITCH_INTERVAL, Session, zenoh_config


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
