"""Zenoh sessions of the HAL: configuration (loopback by default, no multicast) and clean shutdown."""

from __future__ import annotations

import json
import os
import sys
import threading
import weakref
from collections.abc import Mapping, Sequence
from typing import Any

import zenoh

from ..errors import HalError
from .protocol import DEFAULT_ENDPOINT
from .security import Security, check_endpoints

__all__ = ["DEFAULT_ENDPOINT", "GIL_SWITCH_INTERVAL", "ZENOH_RUNTIME", "Session", "callback", "zenoh_config"]

# [s] CPython's GIL switch interval while a session is open (CPython's default: 5 ms). A message
# reaches Python in zenoh's callback thread, which must take the GIL from the thread holding it:
# a loopback ping-pong through callback threads has a p99 of 1.3-1.5 ms with 5 ms, 0.3 ms with 0.2 ms.
GIL_SWITCH_INTERVAL = 2e-4

# Zenoh's runtime pools (tokio), read once per process when the first session opens. Zenoh's default
# gives the receive, accept, network and application pools threads of their own; the HAL moves a
# message per tick each way, and on a 2-core machine fewer threads mean fewer hand-overs: one
# application worker that also receives, plus one sender. Bare ping-pong against zenoh's default pools
# (bench/hal.py: baseline_zenoh_default_pools_*), 5 interleaved rounds at load 1.2: robot CPU per round
# trip 106-129 vs 132-159 us and p50 188-211 vs 227-274 us (lower in 5 of 5); p99 not better (lower in 2
# of 5). The environment variable ZENOH_RUNTIME, if set, wins.
ZENOH_RUNTIME = ("(rx: (handover: app), net: (handover: app), acc: (handover: app), app: (worker_threads: 1), "
                 "tx: (worker_threads: 1))")

_open: weakref.WeakSet = weakref.WeakSet()


def zenoh_config(
    *,
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    mode: str = "peer",
    extra: Mapping[str, Any] | None = None,
    security: Security | None = None,
    key_prefix: str | None = None,
) -> zenoh.Config:
    """A Zenoh config: ``mode`` (peer or client), endpoints, multicast scouting off, and Zenoh's TLS,
    authentication and access control from ``security`` (:mod:`.security`; ``key_prefix``, the robot's
    ``servotau/v1/<robot>``, marks the robot side, whose access-control rules name its keys).

    The endpoints are checked against ``security`` first (a tls/ endpoint needs certificates; beyond
    loopback: TLS, and access control on the robot side): HalError before any session opens.
    ``extra`` maps Zenoh config paths (e.g. ``"transport/link/tx/lease"``) to JSON values.
    """
    if mode not in ("peer", "client", "router"):
        raise HalError(f"zenoh mode {mode!r}: expected 'peer', 'client' or 'router'")
    if not listen and not connect:
        raise HalError("zenoh endpoints: expected at least one listen or connect endpoint, e.g. "
                       f"{DEFAULT_ENDPOINT!r}")
    security = security or Security()
    check_endpoints(security, [*listen, *connect], robot_side=key_prefix is not None)
    conf = zenoh.Config()
    settings = {"mode": mode, "scouting/multicast/enabled": False,
                "listen/endpoints": list(listen), "connect/endpoints": list(connect),
                # retry a missing peer after 50 ms (default 1 s): a controller may start before the robot
                "connect/retry": {"period_init_ms": 50, "period_max_ms": 1000, "period_increase_factor": 2},
                **security.zenoh_settings(key_prefix), **(extra or {})}
    for path, value in settings.items():
        try:
            conf.insert_json5(path, json.dumps(value))
        except Exception as exc:  # zenoh raises ZError
            shown = "(password hidden)" if path == "transport/auth/usrpwd" else repr(value)
            raise HalError(f"zenoh config {path} = {shown} rejected: {exc}") from exc
    return conf


class Session:
    """A Zenoh session whose declarations are undeclared and closed on :meth:`close`, at the latest
    when the interpreter exits (zenoh-python's callback threads otherwise block the exit).

    Opening one lowers the interpreter's GIL switch interval to :data:`GIL_SWITCH_INTERVAL` for the
    rest of the process (``sys.setswitchinterval``; a lower value set by the user is kept), and
    the first one in a process lays out zenoh's threads as :data:`ZENOH_RUNTIME` says unless the
    environment variable of that name is set."""

    def __init__(self, config: zenoh.Config):
        os.environ.setdefault("ZENOH_RUNTIME", ZENOH_RUNTIME)
        try:
            self.z = zenoh.open(config)
        except Exception as exc:
            raise HalError(f"cannot open a zenoh session: {exc}") from exc
        if sys.getswitchinterval() > GIL_SWITCH_INTERVAL:
            sys.setswitchinterval(GIL_SWITCH_INTERVAL)
        self._decls: list = []
        self._lock = threading.Lock()
        self.closed = False
        _open.add(self)

    def keep(self, decl):
        """Remember a declaration (publisher, subscriber, token, queryable) to undeclare on close."""
        self._decls.append(decl)
        return decl

    def close(self) -> None:
        with self._lock:
            if self.closed:
                return
            self.closed = True
        for decl in reversed(self._decls):
            try:
                decl.undeclare()
            except Exception:  # already undeclared, session gone
                pass
        self._decls.clear()
        try:
            self.z.close()
        except Exception:
            pass
        _open.discard(self)


def callback(fn, *, direct: bool = False):
    """A zenoh callback handler running ``fn`` in zenoh-python's Python callback thread, or with
    ``direct`` in zenoh's network thread itself (one thread hand-over less per message; ``fn`` then
    delays the next message of that link while it runs: keep it short and never block in it)."""
    return zenoh.handlers.Callback(fn, indirect=not direct)


def _close_all() -> None:
    for s in list(_open):
        s.close()


# Runs before the interpreter joins non-daemon threads (plain atexit would run after, too late).
if hasattr(threading, "_register_atexit"):
    threading._register_atexit(_close_all)
else:  # pragma: no cover
    import atexit

    atexit.register(_close_all)
