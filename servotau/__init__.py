"""servotau: joint-torque control for position-controlled robots without joint-torque sensors.

Implements Del Prete et al., "Implementing Torque Control with High-Ratio Gear Boxes and without
Joint-Torque Sensors" (2015) on a simulated HRP-2-like robot. The sub-packages live at the top of
the repository and install as ``servotau.hal``, ``servotau.estimation``, ``servotau.identification``,
``servotau.control`` and ``servotau.simrobot``.
"""

from .errors import (
    ConfigError,
    ControlError,
    EstimationError,
    HalError,
    IdentificationError,
    SafetyTrip,
    ServotauError,
)

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "ControlError",
    "EstimationError",
    "HalError",
    "IdentificationError",
    "SafetyTrip",
    "ServotauError",
    "__version__",
]
