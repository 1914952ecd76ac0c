"""Pure numpy signal tools shared by the estimator, the actuator model and the workbench."""

from .savgol import CausalSavgol, causal_coeffs, delay, savgol_centred

__all__ = ["CausalSavgol", "causal_coeffs", "delay", "savgol_centred"]
