"""Hardware abstraction layer: one interface for the simulated and the real robot."""

from .backend import Backend, JointCommand
from .errors import EndOfLog, MalformedMessage, ProtocolVersionMismatch, RobotLost
from .factory import BACKENDS, import_object, open_backend, overrides_from_args, safety_config, server_config
from .firmware import Firmware, FirmwareState, SafetyConfig
from .inprocess import InProcessBackend
from .log import LogReader, LogWriter, finalize_log, frames, read_log
from .protocol import PROTOCOL_VERSION, Keys, keys
from .replay import ReplayBackend
from .served import ServedRobot
from .server import RobotServer, ServerConfig, serve
from .types import (
    FT_SENSOR_NAMES,
    STATUS_INVALID,
    STATUS_NAMES,
    STATUS_OK,
    STATUS_SATURATED,
    STATUS_STALE,
    RobotInfo,
    SensorFrame,
)
from .zenoh_backend import ZenohBackend

__all__ = [
    "BACKENDS",
    "Backend",
    "EndOfLog",
    "FT_SENSOR_NAMES",
    "Firmware",
    "FirmwareState",
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
    "finalize_log",
    "frames",
    "import_object",
    "keys",
    "open_backend",
    "overrides_from_args",
    "read_log",
    "safety_config",
    "serve",
    "server_config",
]
