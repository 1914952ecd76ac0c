"""The HRP-2-like robot: its model file and the names the rest of the code agrees on.

One home for each: the MJCF file (read by MuJoCo in the simulator and by Pinocchio in the estimator
and the controller), the free-flyer root joint, the 30 actuated joints in the HAL order, the F/T
sensors and the model frame (MJCF site) of each, and the half-sitting keyframe.
Nothing here imports MuJoCo or Pinocchio.
"""

from __future__ import annotations

from pathlib import Path
from types import MappingProxyType

MODEL_PATH: Path = Path(__file__).resolve().parent / "hrp2.xml"
"""The robot's MJCF file."""

ROOT_JOINT = "root"
"""Name of the free joint of the waist body ``BODY`` (Pinocchio's joint 1, the free flyer)."""

HALF_SITTING = "half_sitting"
"""Name of the half-sitting keyframe."""

JOINT_NAMES: tuple[str, ...] = (
    *(f"RLEG_JOINT{i}" for i in range(6)),
    *(f"LLEG_JOINT{i}" for i in range(6)),
    "CHEST_JOINT0",
    "CHEST_JOINT1",
    "HEAD_JOINT0",
    "HEAD_JOINT1",
    *(f"RARM_JOINT{i}" for i in range(7)),
    *(f"LARM_JOINT{i}" for i in range(7)),
)
"""The 30 actuated joints in the HRP-2 order (the HAL joint order)."""

FT_FRAMES: MappingProxyType[str, str] = MappingProxyType({
    "right_ankle": "ft_right_ankle",
    "left_ankle": "ft_left_ankle",
    "right_wrist": "ft_right_wrist",
    "left_wrist": "ft_left_wrist",
})
"""HAL F/T sensor name -> model frame (MJCF site, a Pinocchio frame of the same name), in the row order
of :attr:`servotau.hal.types.SensorFrame.wrenches`. The MJCF defines the sensors ``<site>_force`` and
``<site>_torque`` on each site."""

FT_SENSOR_NAMES: tuple[str, ...] = tuple(FT_FRAMES)
"""The four F/T sensors, in the row order of :attr:`servotau.hal.types.SensorFrame.wrenches`."""

FT_SENSOR_FRAMES: tuple[str, ...] = tuple(FT_FRAMES.values())
"""Model frame of each F/T sensor, in :data:`FT_SENSOR_NAMES` order."""
