"""Fit quality: residual RMS and the over-estimation rate of paper section 3.3.

Over-estimation means the model asks for a larger position error than the data needed, in the
direction of the data: with ``s = sign(dq_err)``, sample i is over-estimated when
``s_i * (model_i - dq_err_i) > 0``. A sample with ``dq_err_i == 0`` exactly is over-estimated
whenever ``model_i != 0`` (any nonzero prediction exceeds ``|0|``). This is the quantity that the
asymmetric penalty of eq. 8 weighs ``w`` times more.
"""

from __future__ import annotations

import numpy as np

from .validation import as_samples, check_same_length


def signed_excess(model: np.ndarray, dq_err: np.ndarray) -> np.ndarray:
    """Per-sample over-estimation ``z`` [rad]: > 0 over-estimates ``|dq_err|``, < 0 under-estimates.

    ``z = sign(dq_err) * (model - dq_err)``, and ``z = |model|`` where ``dq_err == 0``.
    """
    s = np.sign(dq_err)
    z = s * (model - dq_err)
    zero = s == 0
    if zero.any():
        z[zero] = np.abs(model[zero])
    return z


def overestimation_rate(model: np.ndarray, dq_err: np.ndarray) -> float:
    """Fraction of samples in [0, 1] where the model over-estimates ``|dq_err|`` (see module doc)."""
    model = as_samples("model", model)
    dq_err = as_samples("dq_err", dq_err)
    n = check_same_length({"model": model, "dq_err": dq_err})
    if n == 0:
        return 0.0
    return float(np.count_nonzero(signed_excess(model, dq_err) > 0.0) / n)


def residual_rms(model: np.ndarray, dq_err: np.ndarray) -> float:
    """Root mean square of ``model - dq_err`` [rad]."""
    r = np.asarray(model, dtype=np.float64) - np.asarray(dq_err, dtype=np.float64)
    return float(np.sqrt(np.mean(r * r))) if r.size else 0.0
