"""What a robot process serves: the interface the simulator (and a real-robot bridge) implements."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from ..types import GroundTruth, RobotInfo, SensorFrame


@runtime_checkable
class ServedRobot(Protocol):
    """A robot driven one period at a time by :class:`~servotau.hal.robot.server.RobotServer` or
    :class:`~servotau.hal.backends.inprocess.InProcessBackend`, behind the robot-side firmware."""

    info: RobotInfo

    def read(self) -> SensorFrame:
        """Sensors of the current tick (same seq until the next :meth:`step`)."""

    def step(self, q_des: np.ndarray) -> None:
        """Apply desired angles [rad] (``info.joint_names`` order) for one period, advance one tick."""

    def servo_off(self) -> None:
        """Cut the servos (latched): no motor current from now on; :meth:`step` still advances time."""

    # Optional: ``servo_on()`` turns the servos back on after servo_off() (the operator's reset,
    # hal/robot/operator.py); a robot without it is reset by restarting its process.

    def ground_truth(self) -> GroundTruth | None:
        """Simulator state of the current tick; None on a real robot."""
