"""How a robot is served: ``[hal.server]`` (:class:`ServerConfig`) and ``[hal.safety]`` (the firmware's
:class:`~servotau.hal.robot.firmware.SafetyConfig`), read without Zenoh."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from servotau.config import Section

from ..config import endpoint_list, with_override
from ..errors import HalError
from ..registry import hal_section
from ..wire.protocol import DEFAULT_ENDPOINT
from .firmware import SafetyConfig
from .realtime import check_priority

CLOCKS = ("lockstep", "realtime", "robot")


@dataclass(frozen=True)
class ServerConfig:
    """How a robot is served (``[server]`` table of a config, see :meth:`from_section`)."""

    robot: str | None = None  # robot name in the key expressions; None: RobotInfo.name
    listen: tuple[str, ...] = (DEFAULT_ENDPOINT,)
    connect: tuple[str, ...] = ()
    mode: str = "peer"  # zenoh mode: peer, or client of a router
    clock: str = "lockstep"  # lockstep, realtime or robot
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    republish_interval: float = 0.02  # [s] lock-step: republish the frame while waiting for a controller
    log: str | None = None  # Parquet log of what was served (frames, applied q_des, truth)
    max_ticks: int | None = None  # stop after this many steps
    publish_truth: bool = True
    realtime_priority: int = 0  # SCHED_FIFO priority of the process (hal/robot/realtime.py); 0: ordinary scheduling

    def __post_init__(self):
        if self.clock not in CLOCKS:
            raise HalError(f"server clock {self.clock!r}: expected one of {list(CLOCKS)}")
        check_priority(self.realtime_priority, "server realtime_priority")

    @classmethod
    def from_section(cls, s: Section, safety: SafetyConfig | None = None) -> ServerConfig:
        """Read robot, listen, connect, mode, clock, republish_interval, log, max_ticks, publish_truth;
        every error names the file and the field (see :func:`server_config`)."""
        s.check_keys(["robot", "listen", "connect", "mode", "clock", "republish_interval", "log", "max_ticks",
                      "publish_truth", "realtime_priority"])
        connect = endpoint_list(s, "connect", [])
        return cls(
            robot=s.str("robot") if "robot" in s else None,
            listen=tuple(endpoint_list(s, "listen", [] if connect else [DEFAULT_ENDPOINT])),
            connect=tuple(connect),
            mode=s.str("mode", "peer", choices=["peer", "client"]),
            clock=s.str("clock", "lockstep", choices=CLOCKS),
            safety=safety or SafetyConfig(),
            republish_interval=s.float("republish_interval", 0.02, min=0, strict_min=True, unit="s"),
            log=s.str("log") if "log" in s else None,
            max_ticks=s.int("max_ticks", min=1) if "max_ticks" in s else None,
            publish_truth=s.bool("publish_truth", True),
            realtime_priority=s.int("realtime_priority", 0, min=0, max=99),
        )


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
