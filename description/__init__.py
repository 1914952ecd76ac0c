"""The robot description: the model file, the one Pinocchio loader and the names of joints and sensors.

Importing this package loads neither MuJoCo nor Pinocchio: :func:`load_pinocchio` imports Pinocchio
on first use (the HAL's types read the sensor names from here).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .robot import (
    FT_FRAMES,
    FT_SENSOR_FRAMES,
    FT_SENSOR_NAMES,
    HALF_SITTING,
    JOINT_NAMES,
    MODEL_PATH,
    ROOT_JOINT,
)

if TYPE_CHECKING:
    from .pinocchio_model import load_pinocchio

__all__ = [
    "FT_FRAMES",
    "FT_SENSOR_FRAMES",
    "FT_SENSOR_NAMES",
    "HALF_SITTING",
    "JOINT_NAMES",
    "MODEL_PATH",
    "ROOT_JOINT",
    "load_pinocchio",
]


def __getattr__(name: str):
    if name == "load_pinocchio":
        from .pinocchio_model import load_pinocchio

        return load_pinocchio
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
