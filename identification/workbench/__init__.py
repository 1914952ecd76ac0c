"""Model workbench: compare the actuator model with measurements, see where it fails, name the missing
physical effect, add it and watch the held-out error fall (docs/workbench.md).

Plotting (:mod:`.report`) is imported only when used. The command line, its Rerun views and the simulated
logs are applications (:mod:`servotau.apps.model`, :mod:`servotau.apps.model_rerun`, :mod:`servotau.apps.simlog`).
"""

from servotau.actuator import (
    ONLINE_SIGNALS,
    Effect,
    Excitation,
    OnlineModel,
    OnlineTerm,
    Signals,
    effect_names,
    excitation_report,
    get_effect,
    predict_batch,
    register_effect,
    unregister_effect,
)

from ..data import write_table
from ..data.folds import blocked_folds, folds_of
from .data import Dataset, align_torque, load_dataset
from .diagnose import MIN_GAIN, Candidate, Confusion, Diagnosis, diagnose
from .evaluate import Comparison, Metrics, compare
from .ladder import Ladder, Rung, add_effects, save_model
from .model import FittedModel, ModelSpec, Term, fit_spec, parse_spec, resolve_shapes
from .views import ResidualViews, residual_views

__all__ = [
    "MIN_GAIN",
    "ONLINE_SIGNALS",
    "Candidate",
    "Comparison",
    "Confusion",
    "Dataset",
    "Diagnosis",
    "Effect",
    "Excitation",
    "FittedModel",
    "Ladder",
    "Metrics",
    "ModelSpec",
    "OnlineModel",
    "OnlineTerm",
    "ResidualViews",
    "Rung",
    "Signals",
    "Term",
    "add_effects",
    "align_torque",
    "blocked_folds",
    "compare",
    "diagnose",
    "effect_names",
    "excitation_report",
    "fit_spec",
    "folds_of",
    "get_effect",
    "load_dataset",
    "parse_spec",
    "predict_batch",
    "register_effect",
    "residual_views",
    "resolve_shapes",
    "save_model",
    "unregister_effect",
    "write_table",
]
