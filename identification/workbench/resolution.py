"""The encoder's resolution read off the log, and the error floor it sets.

A quantised angle ``q = k res`` carries an error up to ``res / 2``, about ``res / sqrt(12)`` RMS, that is a
function of the true angle: on the holds it is a constant offset, the same wherever the joint returns to the same
angle. Any term that sets apart holding from moving, or a function of the position, can fit it. The diagnosis
therefore names no effect whose removed error (RMS, ``sqrt(E_base^2 - E_with^2)``) stays within that floor
(:func:`quantisation_floor`, :func:`within_resolution`; a probe's gain likewise, :func:`probes_within_resolution`):
below the encoder's resolution, the log cannot tell a physical effect from the encoder's rounding.

An encoder that is not quantised sets the floor with its white noise instead (the robust level of the fourth
difference of ``q``, :func:`~servotau.actuator.excitation.noise_floor`): the target holds that noise sample by
sample, and a term that reads ``q`` at the same sample (an acceleration from the angles around it) fits part of it.

The regressors' noise sets two more floors: the fits read the noisy torque and velocity, so the residual carries
``k_tau`` times the torque's noise left after smoothing (:func:`torque_noise_floor`) and ``k_v`` times the velocity's
(:func:`velocity_noise_floor`). A term that is a noise-free function of other signals (the command's history, the
acceleration, the position) can stand in for part of the torque or the velocity, and removes up to that much error
held out without any physical effect (errors in the variables). The floors add in quadrature (:func:`error_floor`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from servotau.actuator.terms import K_TAU, K_V

__all__ = ["encoder_resolution", "error_floor", "probes_within_resolution", "quantisation_floor", "removed_error",
           "torque_noise_floor", "velocity_noise_floor", "within_resolution"]

LATTICE_SHARE = 0.95  # of the steps between distinct angles that must be whole multiples of the smallest one
LATTICE_TOL = 1e-3  # [steps] how close to a whole multiple


def encoder_resolution(q: np.ndarray) -> float:
    """The step [rad] of the lattice the angles ``q`` sit on, or 0 when they sit on none (not quantised, or too
    finely for float64 to tell): the smallest step between distinct angles, when at least ``LATTICE_SHARE`` of
    the steps are whole multiples of it."""
    v = np.unique(np.asarray(q, dtype=float)[np.isfinite(q)])
    if v.size < 3:
        return 0.0
    steps = np.diff(v)
    scale = max(float(np.max(np.abs(v))), 1.0)
    steps = steps[steps > 1e-12 * scale]
    if steps.size < 2:
        return 0.0
    res = float(np.min(steps))
    k = steps / res
    if np.mean(np.abs(k - np.round(k)) < LATTICE_TOL) < LATTICE_SHARE:
        return 0.0
    return res


def quantisation_floor(resolution: float) -> float:
    """RMS [rad] of the rounding error of an encoder of ``resolution`` [rad]: ``resolution / sqrt(12)``."""
    return float(resolution) / np.sqrt(12.0)


def _noise_gain(ds, key: str, deriv: int) -> float:
    """The white-noise gain of the centred SG filter applied here to signal ``key`` (``dq``: derivative 1 of ``q``;
    ``tau``: smoothing): the root of the sum of its squared weights (per second for a derivative), per recording
    weighted by its samples; 1 for a signal that is the log's own."""
    from servotau.signal.savgol import causal_coeffs

    if ds.preprocessing.get(key, {}).get("source") not in ("smoothed", "derivative of q"):
        return 1.0
    total = 0.0
    for p in ds.filter_parts(key):
        if p.window > p.order:
            total += (p.end - p.first) * float(np.sum(causal_coeffs(p.window, p.order, deriv, p.period, "centre") ** 2))
        else:  # filters.differentiate falls back to the central difference
            total += (p.end - p.first) * (0.5 / p.period ** 2 if deriv else 1.0)
    return math.sqrt(total / ds.n)


def torque_noise_floor(ds, k_tau: float) -> float:
    """The torque's noise in the servo error [rad RMS]: ``|k_tau|`` times the white-noise level of the log's torque
    (:func:`~servotau.actuator.excitation.noise_floor` of the raw column) times the noise gain of the smoothing
    applied here. 0 without a torque."""
    from servotau.actuator.excitation import noise_floor

    if not ds.has_torque or not k_tau:
        return 0.0
    sigma = noise_floor(ds.signals["tau_raw"] if "tau_raw" in ds.signals else ds.signals["tau"])
    return abs(k_tau) * sigma * _noise_gain(ds, "tau", 0)


def velocity_noise_floor(ds, k_v: float) -> float:
    """The velocity's noise in the servo error [rad RMS]: ``|k_v|`` times the noise of ``dq``: for a derivative
    taken here, the angle's noise (the encoder's rounding error, else the white-noise level of ``q``) times the
    derivative filter's noise gain; for the log's own velocity, its white-noise level."""
    from servotau.actuator.excitation import noise_floor

    if not k_v or "dq" not in ds.signals:
        return 0.0
    if ds.preprocessing.get("dq", {}).get("source") != "derivative of q":
        return abs(k_v) * noise_floor(ds.signals["dq"])
    res = ds.preprocessing.get("q", {}).get("resolution", 0.0)
    sigma_q = quantisation_floor(res) if res > 0 else noise_floor(ds.signals["q"])
    return abs(k_v) * sigma_q * _noise_gain(ds, "dq", 1)


def error_floor(ds, loss, coefficients: Mapping[str, float] | None = None) -> float:
    """The error [rad RMS] no effect can be told within, for the dataset ``ds`` (``q_des - q``, least-squares
    ``loss``; else 0): the encoder's rounding error, and the torque's and the velocity's noise through the base
    model's ``coefficients`` (``k_tau``, ``k_v``), in quadrature (module doc)."""
    return math.sqrt(sum(x ** 2 for x in _floors(ds, loss, coefficients).values()))


def _floors(ds, loss, coefficients: Mapping[str, float] | None) -> dict[str, float]:
    if not ds.actuator or loss.kind != "least_squares":
        return {}
    coefficients = coefficients or {}
    encoder, floor = _encoder_floor(ds)
    return {encoder: floor,
            "the torque's noise times k_tau": torque_noise_floor(ds, coefficients.get(K_TAU, 0.0)),
            "the velocity's noise times k_v": velocity_noise_floor(ds, coefficients.get(K_V, 0.0))}


def _encoder_floor(ds) -> tuple[str, float]:
    """The encoder's own error in the servo error ``q_des - q`` [rad RMS], and what it is: the rounding error of a
    quantised angle, else the white noise of ``q`` from its fourth difference
    (:func:`~servotau.actuator.excitation.noise_floor`: a smooth motion hardly enters it even at coarse periods). The
    target holds it sample by sample, and so does every term that reads ``q`` at that sample (an acceleration from
    the angles around it, the command's lead): such a term fits part of it held out without any physical effect."""
    from servotau.actuator.excitation import noise_floor

    res = ds.preprocessing.get("q", {}).get("resolution", 0.0)
    if res > 0 or "q" not in ds.signals:
        return "the encoder's rounding error", quantisation_floor(res)
    return "the encoder's noise", noise_floor(ds.signals["q"], difference=4)


def _floor_text(ds, loss, coefficients: Mapping[str, float] | None) -> str:
    """The floor (:func:`error_floor`, not 0) and what it is made of, for the reasons."""
    floors = _floors(ds, loss, coefficients)
    parts = [f"{k} {1e6 * v:.3g} urad RMS" for k, v in floors.items() if v > 0]
    if len(parts) < 2:
        return parts[0]
    total = math.sqrt(sum(v ** 2 for v in floors.values()))
    return f"{1e6 * total:.3g} urad RMS: {', '.join(parts)}, in quadrature"


def within_resolution(ds, ranking: list, e0: float, loss, min_gain: float,
                      coefficients: Mapping[str, float] | None = None) -> list:
    """``ranking`` (the diagnosis's candidates) with the effects that would be named but remove no more error than
    the floor (:func:`error_floor`) made untestable, saying so (least squares only: the errors are RMS); ``e0`` the
    base model's held-out error, ``coefficients`` its coefficients."""
    floor = error_floor(ds, loss, coefficients)
    if floor <= 0:
        return ranking
    out = []
    for c in ranking:
        removed = removed_error(e0, c.heldout_error)
        if c.testable and c.heldout_gain >= min_gain and removed <= floor:
            c = replace(c, testable=False, reason=(
                f"cannot tell: removes {1e6 * removed:.3g} urad RMS, within the log's noise floor "
                f"({_floor_text(ds, loss, coefficients)})"))
        out.append(c)
    return out


def removed_error(e0: float, e1: float) -> float:
    """The error [RMS] a term removes when it takes the held-out error from ``e0`` to ``e1``."""
    return math.sqrt(max(e0 ** 2 - e1 ** 2, 0.0))


def probes_within_resolution(ds, probes: dict[str, float], e0: float, loss,
                             coefficients: Mapping[str, float] | None = None
                             ) -> tuple[dict[str, float], tuple[str, ...]]:
    """``probes`` with the gains that remove no more error than the floor set to 0, and a sentence for each (see
    :func:`within_resolution`)."""
    floor = error_floor(ds, loss, coefficients)
    if floor <= 0:
        return probes, ()
    out, notes = dict(probes), []
    for k, g in probes.items():
        removed = removed_error(e0, e0 * (1.0 - g)) if g > 0 else 0.0
        if 0 < removed <= floor:
            out[k] = 0.0
            if g >= 0.05:
                notes.append(f"cannot tell: the {k} probe removes {1e6 * removed:.3g} urad RMS ({100 * g:.0f} %), "
                             f"within the log's noise floor ({_floor_text(ds, loss, coefficients)})")
    return out, tuple(notes)
