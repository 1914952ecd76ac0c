"""servotau.control: joint-torque control through the position servo (Del Prete et al. 2015, section 4).

An application builds a :class:`ControlManager` and calls :meth:`ControlManager.tick` once per period;
the pieces (inverse dynamics, torque controller, gain conversions, safety) are usable on their own.
"""

from .config import AXES, DEFAULT_PATH, ControlConfig, ForceTask, JointGains, SafetyLimits
from .dynamics import BaseState, RobotDynamics
from .gains import (
    NativeGains,
    TorqueGains,
    k6_from_ks,
    k7_from_kd,
    k8_from_kp,
    k9_from_kf,
    kd_from_k7,
    kf_from_k9,
    kp_from_k8,
    ks_from_k6,
    native_from_torque,
    torque_from_native,
)
from .inverse_dynamics import InverseDynamics
from .law import TorqueControlLaw
from .manager import ControlManager, Mode, StateEstimate
from .safety import CHECKS, SafetyMonitor, SafetyReport
from .terms import COMPONENTS, ControlTerms
from .torque import JointTorqueController

__all__ = [
    "AXES",
    "BaseState",
    "CHECKS",
    "COMPONENTS",
    "ControlConfig",
    "ControlManager",
    "ControlTerms",
    "DEFAULT_PATH",
    "ForceTask",
    "InverseDynamics",
    "JointGains",
    "JointTorqueController",
    "Mode",
    "NativeGains",
    "RobotDynamics",
    "SafetyLimits",
    "SafetyMonitor",
    "SafetyReport",
    "StateEstimate",
    "TorqueControlLaw",
    "TorqueGains",
    "k6_from_ks",
    "k7_from_kd",
    "k8_from_kp",
    "k9_from_kf",
    "kd_from_k7",
    "kf_from_k9",
    "kp_from_k8",
    "ks_from_k6",
    "native_from_torque",
    "torque_from_native",
]
