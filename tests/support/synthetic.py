"""Synthetic single-joint logs with a known truth, for the workbench and the ``servotau model`` tests."""

from __future__ import annotations

import numpy as np

__all__ = ["K_C", "K_TAU", "K_V", "cogging_truth", "friction_recording", "synthetic_table", "two_sine_log"]

K_TAU, K_V, K_C = 5e-5, 6e-3, 1.3e-4  # [rad/(N m)], [rad/(rad/s)], [rad]


def synthetic_table(extra=None, *, seconds=12.0, seed=0, noise=1e-5, reversals=True) -> dict[str, np.ndarray]:
    """A single-joint log ``t, q, q_des, tau, dq, segment`` of ``dq_err = k_tau tau + k_v dq + k_c sign + extra``
    plus white encoder noise.

    ``extra(t, q, dq, tau) -> [rad]`` is the hidden effect. Motion: sines with reversals and holds (or a
    one-way ramp without reversals); torque: slow sines of +/- 30 N m.
    """
    rng = np.random.default_rng(seed)
    dt = 1e-3
    t = np.arange(int(seconds / dt)) * dt
    if reversals:
        dq = 0.6 * np.sin(2 * np.pi * 0.45 * t) + 0.25 * np.sin(2 * np.pi * 1.3 * t + 1.0)
        dq *= np.clip(np.sin(2 * np.pi * t / 4.0) * 3, -1, 1) ** 2  # holds between bursts
    else:
        dq = 0.2 + 0.1 * np.sin(2 * np.pi * 0.3 * t)
    q = 0.5 + np.cumsum(dq) * dt
    tau = 30 * np.sin(2 * np.pi * 0.23 * t + rng.uniform(0, 6)) + 8 * np.sin(2 * np.pi * 0.71 * t)
    y = K_TAU * tau + K_V * dq + K_C * np.tanh(dq / 0.005)
    if extra is not None:
        y = y + extra(t, q, dq, tau)
    q_meas = q + noise * rng.standard_normal(len(t))  # the encoder is noisy, the command is not
    return {"t": t, "q": q_meas, "q_des": q + y, "tau": tau, "dq": dq, "segment": np.floor(t / (seconds / 4))}


def cogging_truth(t, q, dq, tau):
    """A position ripple of 0.08 rad period and 0.2 mrad amplitude [rad] (the hidden effect of several tests)."""
    return 2e-4 * np.sin(2 * np.pi * q / 0.08 + 0.3)


def friction_recording(i: int, *, seconds: float, f0: float) -> dict[str, np.ndarray]:
    """Recording ``i`` of one joint's friction torque [N m] = 0.2 + 1.5 sign(v) + 3 v + noise (no servo error, no
    torque column): ``t, v, friction`` at 250 Hz; the velocity's slow sine runs at ``f0 + 0.05 i`` [Hz]."""
    rng = np.random.default_rng(i)
    t = np.arange(0.0, seconds, 0.004)
    v = 0.4 * np.sin(2 * np.pi * (f0 + 0.05 * i) * t) + 0.2 * np.sin(2 * np.pi * 0.9 * t + i)
    f = 0.2 + 1.5 * np.tanh(v / 0.01) + 3.0 * v + 0.02 * rng.standard_normal(t.size)
    return {"t": t, "v": v, "friction": f}


def two_sine_log(dt, noise, seed=0, duration=4.0, with_dq=False) -> dict[str, np.ndarray]:
    """A log ``t, q, q_des, tau`` (optional ``dq``) of two sines (1.5 and 0.4 Hz) sampled every ``dt`` [s], ``q`` with
    white noise of ``noise`` [rad], the torque 5 q plus white noise of 0.05 N m, a servo error of tau / 1000."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, dt)
    q = 0.3 * np.sin(2 * np.pi * 1.5 * t) + 0.1 * np.sin(2 * np.pi * 0.4 * t)
    dq = 0.3 * 2 * np.pi * 1.5 * np.cos(2 * np.pi * 1.5 * t) + 0.1 * 2 * np.pi * 0.4 * np.cos(2 * np.pi * 0.4 * t)
    tau = 5 * q + rng.normal(0, 0.05, len(t))
    cols = {"t": t, "q": q + rng.normal(0, noise, len(t)), "q_des": q + tau / 1000, "tau": tau}
    if with_dq:
        cols["dq"] = dq
    return cols
