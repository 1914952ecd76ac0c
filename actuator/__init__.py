"""The actuator model: the paper's ``dq_err = k_tau tau + k_v dq`` plus named effects, one file per effect.

- :mod:`.model`: :class:`MotorModel` (one joint), :class:`EffectTerm`, :class:`FitMetrics`;
- :mod:`.motor_file`: :class:`MotorParameters`, the motor file (``config/motors/*.toml``): read and write;
- :mod:`.registry`: :class:`Effect` and the registry that finds the files of :mod:`.effects`;
- :mod:`.online`: the evaluator, on arrays (:func:`predict_batch`) or one tick at a time (:class:`OnlineModel`);
- :mod:`.signals`, :mod:`.excitation`: what effects read, and what the data must exercise to test them.

Identification writes motor files; control, estimation and the model workbench read them through this package.
"""

from .excitation import Excitation, excitation_report
from .loss import LOSS_KINDS, Loss
from .model import EffectTerm, FitMetrics, MotorModel
from .motor_file import FORMAT_VERSION, MotorParameters
from .online import ONLINE_SIGNALS, OnlineModel, checked_online_model, predict_batch, required_signals
from .registry import (
    EXPERIMENTS,
    Effect,
    OnlineTerm,
    builtin_effects,
    effect_names,
    get_effect,
    register_effect,
    resolve_effects,
    unregister_effect,
)
from .signals import Signals
from .terms import K_C, K_TAU, K_V, ModelTerms

__all__ = [
    "EXPERIMENTS",
    "FORMAT_VERSION",
    "K_C",
    "K_TAU",
    "K_V",
    "LOSS_KINDS",
    "ONLINE_SIGNALS",
    "Effect",
    "EffectTerm",
    "Excitation",
    "FitMetrics",
    "Loss",
    "ModelTerms",
    "MotorModel",
    "MotorParameters",
    "OnlineModel",
    "OnlineTerm",
    "Signals",
    "builtin_effects",
    "checked_online_model",
    "effect_names",
    "excitation_report",
    "get_effect",
    "predict_batch",
    "register_effect",
    "required_signals",
    "resolve_effects",
    "unregister_effect",
]
