"""The estimator the controller runs with: config/estimation.toml's ``low_delay`` variant (one home for the loop,
its stability model and the tasks' feasibility check)."""

from __future__ import annotations

from servotau.estimation import EstimatorConfig

ESTIMATOR_VARIANT = "low_delay"  # the estimator variant the torque controller is stable with in simulation


def estimator_config() -> EstimatorConfig:
    """config/estimation.toml with the loop's variant (:data:`ESTIMATOR_VARIANT`)."""
    return EstimatorConfig.from_toml(variant=ESTIMATOR_VARIANT)
