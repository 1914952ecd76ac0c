"""servotau.estimation: joint torques from encoders, IMU and F/T sensors (Del Prete et al. 2015, section 2)."""

from servotau.signal.savgol import CausalSavgol, savgol_centred

from .calibration import (
    FtOffsetAverage,
    Payload,
    calibrate_ft_offsets,
    calibrate_gyro_bias,
    identify_payload,
    payload_samples,
)
from .config import EstimatorConfig, FilterSettings, ModelPerturbation, PredictionSettings
from .delay_line import DelayLine
from .dynamics import InverseDynamics
from .estimator import Estimate, TorqueEstimator
from .model import EstimatorModel, JointAddress, perturb_inertias
from .offline import OfflineEstimate, estimate_offline, frames_to_arrays, replay
from .prediction import ModelPredictor

__all__ = [
    "CausalSavgol",
    "DelayLine",
    "Estimate",
    "EstimatorConfig",
    "EstimatorModel",
    "FilterSettings",
    "InverseDynamics",
    "JointAddress",
    "ModelPerturbation",
    "ModelPredictor",
    "OfflineEstimate",
    "Payload",
    "PredictionSettings",
    "TorqueEstimator",
    "FtOffsetAverage",
    "calibrate_ft_offsets",
    "calibrate_gyro_bias",
    "estimate_offline",
    "frames_to_arrays",
    "identify_payload",
    "payload_samples",
    "perturb_inertias",
    "replay",
    "savgol_centred",
]
