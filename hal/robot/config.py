"""How a robot is served: ``[hal.server]`` (:class:`ServerConfig`) and ``[hal.safety]`` (the firmware's
:class:`~servotau.hal.robot.firmware.SafetyConfig`), read without Zenoh."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from servotau.config import Section, check_settings, load_dataclass, setting

from ..config import endpoint_list, with_override
from ..errors import HalError
from ..registry import hal_section
from ..wire.protocol import DEFAULT_ENDPOINT
from ..wire.security import SECURITY_KEYS, Security, check_endpoints, field_error, security_from_section
from .firmware import SafetyConfig
from .realtime import check_priority

CLOCKS = ("lockstep", "realtime", "robot")
MODES = ("peer", "client")
"""Zenoh modes: a peer, or a client of a router."""


@dataclass(frozen=True)
class ServerConfig:
    """How a robot is served (``[server]`` table of a config, see :meth:`from_section`)."""

    robot: str | None = setting(None)  # robot name in the key expressions; None: RobotInfo.name
    listen: tuple[str, ...] = setting((DEFAULT_ENDPOINT,))  # the default when connect is empty, else ()
    connect: tuple[str, ...] = setting(())
    mode: str = setting("peer", choices=MODES)  # zenoh mode: peer, or client of a router
    clock: str = setting("lockstep", choices=CLOCKS)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    republish_interval: float = setting(0.02, unit="s", min=0, strict_min=True)  # lock-step: republish the frame
    # while waiting for a controller
    log: str | None = setting(None)  # Parquet log of what was served (frames, applied q_des, truth)
    max_ticks: int | None = setting(None, min=1)  # stop after this many steps
    publish_truth: bool = setting(True)
    realtime_priority: int = setting(0, min=0, max=99)  # SCHED_FIFO priority of the process (hal/robot/realtime.py);
    # 0: ordinary scheduling
    security: Security = field(default_factory=Security)  # TLS, authentication, access control (hal/wire/security.py)

    def __post_init__(self):
        check_settings(self, HalError)
        check_priority(self.realtime_priority, "server realtime_priority")

    @classmethod
    def from_section(cls, s: Section, safety: SafetyConfig | None = None) -> ServerConfig:
        """Read robot, listen, connect, mode, clock, republish_interval, log, max_ticks, publish_truth;
        every error names the file and the field (see :func:`server_config`)."""
        s.check_keys([f for f in cls.__dataclass_fields__ if f not in ("safety", "security")] + list(SECURITY_KEYS))
        connect = endpoint_list(s, "connect", list(cls.connect))
        listen = endpoint_list(s, "listen", [] if connect else list(cls.listen))
        security = security_from_section(s, robot_side=True)
        try:
            check_endpoints(security, listen + connect, robot_side=True)
        except HalError as exc:
            raise field_error(s, "listen" if listen else "connect", exc) from None
        return load_dataclass(cls, s, ignore=SECURITY_KEYS, listen=tuple(listen), connect=tuple(connect),
                              safety=safety or SafetyConfig(), security=security)


def safety_config(config: Section | str | Path) -> SafetyConfig:
    """Robot-side firmware settings from ``[hal.safety]`` (defaults if absent)."""
    return SafetyConfig.from_section(hal_section(config).section("safety", {}))


def server_config(config: Section | str | Path, *, port: int | None = None) -> ServerConfig:
    """:class:`ServerConfig` from ``[hal.server]`` and ``[hal.safety]`` (``port``: listen on
    ``tcp/127.0.0.1:<port>`` instead of the configured endpoints)."""
    s = hal_section(config)
    srv = s.section("server", {})
    if port is not None:
        srv = with_override(srv, "listen", [f"tcp/127.0.0.1:{port}"], "--port")
    return ServerConfig.from_section(srv, safety_config(s))
