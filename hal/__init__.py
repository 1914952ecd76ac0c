"""Hardware abstraction layer: one interface for the simulated and the real robot."""

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

__all__ = [
    "FT_SENSOR_NAMES",
    "STATUS_INVALID",
    "STATUS_NAMES",
    "STATUS_OK",
    "STATUS_SATURATED",
    "STATUS_STALE",
    "RobotInfo",
    "SensorFrame",
]
