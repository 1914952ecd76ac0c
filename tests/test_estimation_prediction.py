"""Tests of the actuator-model prediction (estimation/prediction.py) on an exact synthetic actuator."""

import numpy as np
import pytest

from servotau.errors import EstimationError
from servotau.estimation.config import PredictionSettings
from servotau.estimation.prediction import ModelPredictor
from servotau.signal.savgol import delay

DT = 1e-3  # [s]
K_TAU = np.array([1e-4, 2e-4])  # [rad/(N m)]
K_V = np.array([5e-3, 1e-2])  # [rad s/rad]


def signals(t):
    """Joint angle [rad], velocity [rad/s] and torque [N m] of two joints."""
    w = 2 * np.pi * np.array([0.5, 0.8])
    return 0.3 * np.sin(w * t), 0.3 * w * np.cos(w * t), 10.0 * np.sin(1.4 * w * t + 0.3) + 3.0


def run(bias: float, window: int = 40):
    """Feed an exact actuator (plus a constant model bias [N m]); return times, predictions, delayed torques."""
    settings = PredictionSettings(k_tau={"a": 1e-4, "b": 2e-4}, k_v={"a": 5e-3, "b": 1e-2})
    pred = ModelPredictor(("a", "x", "b"), settings, DT, window, 2, "centre", 0)
    d = delay(window, 2, 0, "centre") * DT
    out = np.zeros(3)
    rows = []
    for k in range(1, 1500):
        t = k * DT
        q_prev, dq_prev, _ = signals(t - DT)
        q, _, tau = signals(t)
        q_des = q_prev + K_TAU * (tau + bias) + K_V * dq_prev  # the servo's law, start-of-period state
        _, _, tau_late = signals(t - d)  # an ideal estimator, late by the filter delay
        pred.update(np.array([q[0], 0.0, q[1]]), np.array([q_des[0], 0.0, q_des[1]]))
        pred.predict(np.array([tau_late[0], 0.0, tau_late[1]]), out)
        rows.append((t, out[[0, 2]].copy(), tau_late, tau, np.isnan(out[1])))
    return rows


@pytest.mark.parametrize("bias", [0.0, 2.0])
def test_prediction_removes_the_filter_delay_of_an_exact_actuator(bias):
    """With an exact actuator model (even biased) the prediction removes the filter delay."""
    rows = [r for r in run(bias) if r[0] > 0.3]
    pred = np.array([r[1] for r in rows])
    late = np.array([r[2] for r in rows])
    true = np.array([r[3] for r in rows])
    assert np.all(np.isfinite(pred)) and all(r[4] for r in rows)  # joint "x" has no model: NaN
    assert np.abs(pred - true).max() < 0.2
    assert np.abs(late - true).max() > 1.0


def test_prediction_is_nan_until_ready_and_without_command():
    """No prediction before the filter is full of model torques, nor for a tick without q_des."""
    settings = PredictionSettings(k_tau={"a": 1e-4}, k_v={"a": 5e-3})
    pred = ModelPredictor(("a",), settings, DT, 40, 2, "centre", 0)
    out = np.zeros(1)
    for k in range(80):  # 20 samples fill the velocity filter, then 40 model torques the centred filter
        pred.update(np.array([0.01 * k]), np.array([0.01 * k]))
        pred.predict(np.zeros(1), out)
        assert np.isnan(out[0]) == (k < 59)
    pred.update(np.array([0.5]), None)
    pred.predict(np.zeros(1), out)
    assert np.isnan(out[0])


def test_unknown_joint_or_bad_command_raises():
    """Motor parameters for an unknown joint, or a non-finite q_des, raise EstimationError."""
    with pytest.raises(EstimationError, match="zz"):
        ModelPredictor(("a",), PredictionSettings(k_tau={"zz": 1e-4}, k_v={"zz": 0.0}), DT, 40, 2, "centre", 0)
    pred = ModelPredictor(("a",), PredictionSettings(k_tau={"a": 1e-4}, k_v={"a": 0.0}), DT, 40, 2, "centre", 0)
    with pytest.raises(EstimationError, match="q_des"):
        pred.update(np.zeros(1), np.array([np.nan]))
