"""Hardware abstraction layer: one interface for the simulated and the real robot.

By role: the data types (:mod:`.types`), the controller's :class:`Backend` and the backends that implement
it (:mod:`.backends`, found by name in :mod:`.registry`), the robot side (:mod:`.robot`: server,
firmware, what a robot serves), the wire (:mod:`.wire`: message format, Zenoh sessions) and the log.

Importing this package does not load Zenoh: :class:`ZenohBackend`, :class:`RobotServer` and
:func:`serve` are imported on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .backend import Backend, JointCommand
from .backends.inprocess import InProcessBackend
from .backends.replay import ReplayBackend
from .config import import_object
from .errors import EndOfLog, MalformedMessage, ProtocolVersionMismatch, RobotLost
from .log import LogReader, LogWriter, finalize_log, frames, read_log
from .registry import BACKENDS, available_backends, backend_names, open_backend, overrides_from_args, register
from .robot.config import ServerConfig, safety_config, server_config
from .robot.firmware import Firmware, FirmwareState, SafetyConfig
from .robot.served import ServedRobot
from .types import (
    FT_SENSOR_NAMES,
    STATUS_INVALID,
    STATUS_NAMES,
    STATUS_OK,
    STATUS_SATURATED,
    STATUS_STALE,
    GroundTruth,
    RobotInfo,
    SensorFrame,
)
from .wire.protocol import PROTOCOL_VERSION, Keys, keys

if TYPE_CHECKING:
    from .backends.zenoh import ZenohBackend
    from .robot.server import RobotServer, serve

_LAZY = {"ZenohBackend": ".backends.zenoh", "RobotServer": ".robot.server", "serve": ".robot.server"}

__all__ = [
    "BACKENDS",
    "Backend",
    "EndOfLog",
    "FT_SENSOR_NAMES",
    "Firmware",
    "FirmwareState",
    "GroundTruth",
    "InProcessBackend",
    "JointCommand",
    "Keys",
    "LogReader",
    "LogWriter",
    "MalformedMessage",
    "PROTOCOL_VERSION",
    "ProtocolVersionMismatch",
    "ReplayBackend",
    "RobotInfo",
    "RobotLost",
    "RobotServer",
    "STATUS_INVALID",
    "STATUS_NAMES",
    "STATUS_OK",
    "STATUS_SATURATED",
    "STATUS_STALE",
    "SafetyConfig",
    "SensorFrame",
    "ServedRobot",
    "ServerConfig",
    "ZenohBackend",
    "available_backends",
    "backend_names",
    "finalize_log",
    "frames",
    "import_object",
    "keys",
    "open_backend",
    "overrides_from_args",
    "read_log",
    "register",
    "safety_config",
    "serve",
    "server_config",
]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
