"""Fine-step Euler integrations of the Dahl and LuGre friction states, written independently of the workbench's
regressors (tests/test_actuator_effects_{dahl,lugre}.py generate their hidden effects with them)."""

from __future__ import annotations

import numpy as np

__all__ = ["dahl_euler", "lugre_euler"]


def lugre_euler(dq: np.ndarray, dt: float, x0: float, fs_ratio: float = 1.0, v_s: float = 1.0,
                substeps: int = 20) -> np.ndarray:
    """``w`` with ``dw/dt = v / x0 - |v| w / (x0 G(v))``, ``G = 1 + (fs_ratio - 1) exp(-(v/v_s)^2)``, ``v``
    linear between the samples, explicit Euler with ``substeps`` steps per sample; ``w = 0`` at the first sample."""
    h = dt / substeps
    w = 0.0
    out = np.zeros(len(dq))
    frac = (np.arange(1, substeps + 1) / substeps).tolist()
    for k in range(1, len(dq)):
        v0, v1 = float(dq[k - 1]), float(dq[k])
        for f in frac:
            v = v0 + (v1 - v0) * f
            g = 1.0 + (fs_ratio - 1.0) * np.exp(-((v / v_s) ** 2)) if fs_ratio != 1.0 else 1.0
            w += h * (v - abs(v) * w / g) / x0
        out[k] = w
    return out


def dahl_euler(dq: np.ndarray, dt: float, x0: float, substeps: int = 20) -> np.ndarray:
    """Dahl's ``z`` with ``dz/dx = (1 - z sgn(dx)) / x0`` (LuGre without Stribeck term), same integration."""
    return lugre_euler(dq, dt, x0, substeps=substeps)
