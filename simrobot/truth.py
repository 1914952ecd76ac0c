"""Ground truth of the simulated robot, for evaluation and tests only.

The controller side never reads this: it travels on its own channel (Drake's hardware_sim
pattern), so that a real backend, which has no ground truth, runs the same controller stack.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GroundTruth:
    """What actually happened in the simulator at one tick (joint arrays in RobotInfo order)."""

    time: float  # [s] sim time
    seq: int  # tick number, same as the SensorFrame's
    q: np.ndarray  # [rad] (n,) true joint angles (link side)
    dq: np.ndarray  # [rad/s] (n,) true joint velocities
    tau: np.ndarray  # [N m] (n,) joint torque transmitted to the link (motor through gear minus friction)
    current: np.ndarray  # [A] (n,) motor current after dead zone and saturation
    base_position: np.ndarray  # [m] (3,) waist position in world
    base_quat_wxyz: np.ndarray  # (4,) waist orientation in world, w first
    base_velocity: np.ndarray  # (6,) [m/s, rad/s] linear (world frame) then angular (waist frame)
    wrenches: np.ndarray  # [N, N m] (4, 6) noise-free, offset-free F/T readings (HAL convention)
    external_wrench: np.ndarray  # [N, N m] (6,) operator wrench, world frame, at the pushed body's CoM
    sole_contact_forces: np.ndarray  # [N] (2, 3) total contact force on the right and left sole, world frame

    FIELDS = ("q", "dq", "tau", "current", "base_position", "base_quat_wxyz", "base_velocity", "wrenches",
              "external_wrench", "sole_contact_forces")

    def to_vector(self) -> np.ndarray:
        """Flatten the arrays (FIELDS order) into one float64 vector (time and seq excluded)."""
        return np.concatenate([np.ravel(getattr(self, f)) for f in self.FIELDS])

    @classmethod
    def from_vector(cls, time: float, seq: int, vec: np.ndarray, n_joints: int) -> GroundTruth:
        """Inverse of :meth:`to_vector` for a robot with ``n_joints`` joints."""
        shapes = {"q": (n_joints,), "dq": (n_joints,), "tau": (n_joints,), "current": (n_joints,),
                  "base_position": (3,), "base_quat_wxyz": (4,), "base_velocity": (6,), "wrenches": (4, 6),
                  "external_wrench": (6,), "sole_contact_forces": (2, 3)}
        out, i = {}, 0
        for f in cls.FIELDS:
            size = int(np.prod(shapes[f]))
            out[f] = np.asarray(vec[i : i + size]).reshape(shapes[f])
            i += size
        return cls(time=time, seq=seq, **out)
