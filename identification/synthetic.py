"""Synthetic identification data from a known actuator, for tests, benchmarks and demos.

``dq_err = k_tau tau + k_v dq + k_c sign(dq) + e_deadzone clip(tau / tau_band, -1, 1) + noise``

The last term mimics the driver dead zone of HRP-2 (paper Fig. 1; public figures: a rise of 0.6 to
6 mrad over a 0.3 to 3 N m band of torque): a steep middle segment that no linear model fits.
Defaults are close to the identified HRP-2 hip yaw (k_tau = 2.12e-4 rad/(N m), k_v = 0.013 rad/(rad/s)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class SyntheticData:
    """Samples ``tau`` [N m], ``dq`` [rad/s], ``dq_err`` [rad] and the noise-free ``truth`` [rad]."""

    tau: np.ndarray
    dq: np.ndarray
    dq_err: np.ndarray
    truth: np.ndarray


def make_synthetic(
    m: int,
    *,
    seed: int = 0,
    k_tau: float = 2.12e-4,  # [rad/(N m)]
    k_v: float = 0.013,  # [rad/(rad/s)]
    k_c: float = 5e-4,  # [rad]
    e_deadzone: float = 2e-3,  # [rad]
    tau_band: float = 1.0,  # [N m]
    noise: float = 1e-4,  # [rad] standard deviation
    tau_max: float = 40.0,  # [N m]
    dq_max: float = 1.5,  # [rad/s]
    static_fraction: float = 0.3,
) -> SyntheticData:
    """``m`` samples: a ``static_fraction`` at dq = 0 exactly, the rest with |dq| in [0.05, dq_max]."""
    rng = np.random.default_rng(seed)
    tau = rng.uniform(-tau_max, tau_max, m)
    moving = rng.random(m) >= static_fraction
    dq = np.where(moving, rng.choice([-1.0, 1.0], m) * rng.uniform(0.05, dq_max, m), 0.0)
    truth = k_tau * tau + k_v * dq + k_c * np.sign(dq) + e_deadzone * np.clip(tau / tau_band, -1.0, 1.0)
    return SyntheticData(tau, dq, truth + noise * rng.standard_normal(m), truth)
