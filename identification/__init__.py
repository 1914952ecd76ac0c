"""servotau.identification: actuator-model identification (Del Prete et al. 2015, section 3).

Model per joint: ``dq_err = q_des - q = k_tau tau + k_v dq [+ k_c sign(dq)]``, fitted by least squares
(eq. 7), by the asymmetric penalty (eq. 8, Newton or the QP of eq. 9 with OSQP), in two stages
(section 3.3.1), or as the piecewise-linear model of section 3.2.2. Results are saved per joint in
a TOML motor-parameter file (:class:`MotorParameters`).
"""

from servotau.actuator import EffectTerm, FitMetrics, MotorModel, MotorParameters
from servotau.actuator.loss import Loss

from .asymmetric import asymmetric_cost, fit_asymmetric
from .fit import fit_linear_model, fit_with_loss
from .least_squares import fit_least_squares
from .linear_fit import LinearFit
from .metrics import overestimation_rate, residual_rms, signed_excess
from .piecewise import PiecewiseFit, PiecewiseLinear, fit_piecewise, fit_piecewise_1d
from .regressors import K_C, K_TAU, K_V, Regressors, linear_regressors, sign
from .synthetic import SyntheticData, make_synthetic
from .two_stage import DQ_STATIC, TwoStageFit, fit_two_stage

__all__ = [
    "DQ_STATIC",
    "EffectTerm",
    "FitMetrics",
    "K_C",
    "K_TAU",
    "K_V",
    "LinearFit",
    "Loss",
    "MotorModel",
    "MotorParameters",
    "PiecewiseFit",
    "PiecewiseLinear",
    "Regressors",
    "SyntheticData",
    "TwoStageFit",
    "asymmetric_cost",
    "fit_asymmetric",
    "fit_least_squares",
    "fit_linear_model",
    "fit_piecewise",
    "fit_piecewise_1d",
    "fit_two_stage",
    "fit_with_loss",
    "linear_regressors",
    "make_synthetic",
    "overestimation_rate",
    "residual_rms",
    "sign",
    "signed_excess",
]
