"""``deadzone``: dead zone of the servo (on the position error or the current).

``phi = c + (1 - |c|) z exp(-(dq / v_th)^2)`` with ``c = clip(m / band, -1, 1)``, the servo effort
``m = u - damping_share u_v``, and ``z`` the sign of the last ``|m| > band`` (``v_th = 0``: no latch, ``phi = c``).
A dead band on the position error lets the joint rest anywhere inside it with no servo torque: held by friction
after a push it stays at the edge it was pushed to (``z``); crossing the band freely (fast) it is on average at
the centre.

Crossing form (``crossing = 1``, offered when the log has ``q`` and ``q_des``): ``sign(m)`` outside the band;
inside, ``z + (lead(t) - lead(t_entry)) / width``: the joint is free there and its error follows the command's
lead (``q_des(t - 1) - q(t)``, as for ``saturation``) from the edge it entered at. It is fitted as two columns,
the edge and the lead since the entry; ``width`` [rad], the band's half-width, is the ratio of their coefficients
(the lead's is 1 in theory). Simulated knee, 3 mrad dead band: width 3.4 mrad, fall 0.95 (docs/workbench.md).

On-line: ``tau``, ``dq`` (history if ``v_th > 0``: a latch of the sign of the last effort beyond the band); in
the crossing form also ``q``, ``q_des`` (history: the latch, the last command and the lead at the entry).

The dead band on the holds (the motor files' ``deadzone`` term). HRP-2's motor drivers ignore current commands
below a threshold (public figure: about +/-0.4 A), so the servo produces no torque until its error ``q_des - q``
exceeds a band ``d`` [rad] on either side of the linear prediction. At rest, where the velocity terms vanish, the
paper's model then misses a step::

    dq_err = k_tau tau + d sign(tau)            (at rest: the servo holds the load tau)

The eq. 10 feedforward without ``d`` leaves the position feedback to supply it: the joint drifts until
``K6 e_q = d``, i.e. a static error ``d / K6`` (K6 = 0.1: 10 d). :func:`rest_dead_band` measures ``d`` from the
samples at rest of an identification log (the collection plan's holds, where the operator pushes the torque
through zero): half the jump of the rest residual ``dq_err - k_tau tau`` between positive and negative
torques. Coulomb friction does not enter at rest, which separates the two: this is the experiment of the pair
(``deadzone``, ``coulomb``) below. The fitted term, ranked on held-out data dominated by the sweeps, confuses
them (docs/control.md), so the term of a motor file is the one measured on the holds.

:func:`with_dead_band` puts ``d`` into a motor model as its ``deadzone`` extra term (``damping_share = 0``,
``phi = clip(u / band, -1, 1)`` of the model's predicted command ``u``: the sign of ``tau`` at rest, where ``d``
was measured), replacing the one the workbench fitted if any. The controller's feedforward evaluates it on-line
with ``tau = tau*`` (control/torque.py): it adds ``d`` in the direction of the command it already sends, the
classic dead-zone inverse, smoothed over ``band``. The log's side (reading the holds through the data layer) is
:mod:`servotau.identification.deadband`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from servotau.errors import IdentificationError

from ..excitation import Excitation, has_torque
from ..model import EffectTerm, MotorModel
from ..registry import Effect
from ..signals import (
    Signals,
    bell_of,
    command_lead,
    direction_latch,
    hysteresis,
    sample_lead,
    sign_latch,
    since_onset,
)

ORDER = 50
REST = (0.0, 0.01, 0.05)  # [rad/s] resting below this speed at the last edge (0: no latch)
BANDS = (3e-5, 1e-4, 3e-4, 1e-3)  # [rad] the effort's smoothing band (the detector of the crossing form)
SHARES = (0.0, 0.33, 0.67, 1.0)  # the part of k_v that is the servo's damping (0: a dead band on the error;
# 1: on the driver's current, after the whole PD: then the effort is the torque itself)
DZ_RELEASE = 1.5
"""Crossing form: the joint leaves the band when ``|m|`` exceeds ``DZ_RELEASE band`` and enters it when ``|m|``
falls to ``band`` (hysteresis: the effort hovers at the band's edge during a slow crossing, and each flicker
would restart it from an edge). 1.5 keeps the partner in the dead zone's pair with cogging, which 1 (no
hysteresis) loses; 2 gives lower falls (the three values' falls are in CHANGELOG.md)."""


def deadzone(
    s: Signals, band: float, damping_share: float = 0.0, v_th: float = 0.0, crossing: float = 0.0, width: float = 0.0
) -> np.ndarray:
    """A step of the error at zero servo effort ``m = u - damping_share u_v`` [rad], smoothed over ``band``
    [rad]; with ``v_th > 0`` [rad/s], where the effort is inside the band the joint rests at the edge of the
    dead band it was last pushed against (the sign of the last ``|m| > band``), fading to the band's centre
    as it moves faster than ``v_th`` (crossing the band freely).

    ``crossing = 1``: the crossing form of a dead band on the position error (``v_th`` unused). Outside it
    the step ``sign(m)``; inside, the joint is free and its error follows the command's lead from the edge it
    entered at: ``z + (lead(t) - lead(t_entry)) / width``, ``z`` the sign of the last effort outside,
    ``lead = q_des(t - 1) - q(t)`` (:func:`~servotau.actuator.signals.command_lead`), ``width`` [rad] the
    band's half-width (0: the edge alone). The joint enters the band when ``|m| <= band`` and leaves it when
    ``|m| > DZ_RELEASE band`` (hysteresis). Reads ``q`` and ``q_des``: the target must be ``q_des - q``.
    """
    if crossing:
        edge, lead = _crossing(s, band, damping_share)
        return edge + lead / width if width else edge
    m = s["u"] - damping_share * s["u_v"]
    step = np.clip(m / band, -1.0, 1.0)
    if v_th <= 0.0:
        return step
    rest = direction_latch(m, band, s.starts) * bell_of(s, "dq", v_th)
    return step + (1.0 - np.abs(step)) * rest


def _crossing(s: Signals, band: float, damping_share: float) -> tuple[np.ndarray, np.ndarray]:
    """The two columns of the crossing form: the edge (``sign(m)`` outside the band, inside the sign of the
    last effort outside) and the command's lead since the entry into the band [rad] (0 outside)."""
    m = s["u"] - damping_share * s["u_v"]
    outside = hysteresis(np.abs(m), DZ_RELEASE * band, band, s.starts)
    inside = ~outside
    edge = np.where(inside, sign_latch(m, outside, s.starts), np.sign(m))
    return edge, since_onset(command_lead(s), inside, s.starts)


def columns(
    s: Signals, band: float, damping_share: float = 0.0, v_th: float = 0.0, crossing: float = 0.0, width: float = 0.0
) -> np.ndarray:
    """The step alone, or (crossing form) the edge and the lead since the entry, fitted separately: their
    coefficients are the band's half-width and the part of the lead the error keeps (1 in theory)."""
    if not crossing:
        return deadzone(s, band, damping_share, v_th)
    return np.column_stack(_crossing(s, band, damping_share))


def fold(c: np.ndarray, shape: Mapping[str, float]) -> tuple[float, dict[str, float]]:
    # c_edge edge + c_lead lead = c_edge (edge + lead / width), width = c_edge / c_lead
    if not shape.get("crossing"):
        return float(c[0]), dict(shape)
    return float(c[0]), {**shape, "width": float(c[0] / c[1]) if c[1] != 0.0 else 0.0}


def grid(s: Signals) -> tuple[dict[str, float], ...]:
    """The step (with or without the rest latch) for every band and damping share; with the command and the
    position in the log, the crossing form too, for a dead band on the position error (shares 0 and 0.33:
    inside such a band the servo's damping still acts, so the effort is ``u`` or close to it)."""
    out = [{"band": b, "damping_share": d, "v_th": v} for d in SHARES for b in BANDS for v in REST]
    if "q" in s and "q_des" in s:
        out += [{"band": b, "damping_share": d, "crossing": 1.0} for d in SHARES[:2] for b in BANDS]
    return tuple(out)


def shape_signals(shape: Mapping[str, float]) -> tuple[str, ...]:
    """Signals the term of ``shape`` reads besides its own: ``q`` and ``q_des`` in the crossing form."""
    return ("q", "q_des") if shape.get("crossing") else ()


class DeadzoneOnline:
    """On-line ``deadzone``: the step, the latch of the sign of the last effort beyond the band and, in the
    crossing form, the last command and the lead at the entry into the band."""

    def __init__(self, shape: Mapping[str, float], period: float):
        self.band, self.share, self.v_th = shape["band"], shape.get("damping_share", 0.0), shape.get("v_th", 0.0)
        self.crossing, self.width = bool(shape.get("crossing", 0.0)), shape.get("width", 0.0)
        self.z = 0.0
        self.outside = False  # the detector's state (crossing form: with hysteresis)
        self.inside = False  # the last committed sample was inside the band (False before the first)
        self.q_des_prev: float | None = None  # [rad] the command of the last tick
        self.entry_lead = 0.0  # [rad]

    def _m(self, x: Mapping[str, float]) -> float:
        return x["u"] - self.share * x["u_v"]

    def _outside(self, m: float) -> bool:
        if not self.crossing:
            return abs(m) > self.band
        return abs(m) > (self.band if self.outside else DZ_RELEASE * self.band)  # hysteresis

    def value(self, x: Mapping[str, float]) -> float:
        m = self._m(x)
        outside = self._outside(m)
        if self.crossing:
            if outside:
                return math.copysign(1.0, m)
            if not self.inside or not self.width:  # entering the band at this tick, or the edge alone
                return self.z
            return self.z + (sample_lead(x, self.q_des_prev) - self.entry_lead) / self.width
        step = min(1.0, max(-1.0, m / self.band))
        if self.v_th <= 0.0:
            return step
        z = math.copysign(1.0, m) if outside else self.z
        return step + (1.0 - abs(step)) * z * math.exp(-((x["dq"] / self.v_th) ** 2))

    def commit(self, x: Mapping[str, float]) -> None:
        m = self._m(x)
        self.outside = self._outside(m)
        if self.outside:
            self.z = math.copysign(1.0, m)
        elif self.crossing and not self.inside:
            self.entry_lead = sample_lead(x, self.q_des_prev)
        self.inside = not self.outside
        if self.crossing:
            self.q_des_prev = x["q_des"]


DQ_REST = 0.005  # [rad/s] |dq| below this is at rest
TAU_MIN = 1.0  # [N m] |tau| above this on each side of the reversal (the torque estimate's noise is ~0.1 N m)
MIN_SAMPLES = 200  # at rest on each side of the reversal
BAND = 3e-5  # [rad] of the predicted command u over which the compensation changes sign (3 % of a 1 mrad band)


@dataclass(frozen=True)
class DeadBand:
    """Dead band of one joint from the samples at rest."""

    d: float  # [rad] half the jump of the rest residual at the torque reversal
    offset: float  # [rad] mean of the two sides (0 for a symmetric dead band; an encoder offset otherwise)
    n_positive: int  # samples at rest with tau > TAU_MIN
    n_negative: int  # samples at rest with tau < -TAU_MIN
    spread: float  # [rad] median absolute deviation of the residual on both sides (its noise)


def rest_dead_band(dq_err: np.ndarray, tau: np.ndarray, dq: np.ndarray, k_tau: float, *, dq_rest: float = DQ_REST,
                   tau_min: float = TAU_MIN, min_samples: int = MIN_SAMPLES) -> DeadBand:
    """Dead band [rad] from the samples at rest (``|dq| < dq_rest``) with ``|tau| > tau_min`` on both sides.

    Args:
        dq_err: ``q_des - q`` [rad], aligned with ``tau`` as for the motor fit.
        tau: Estimated joint torque [N m].
        dq: Estimated joint velocity [rad/s].
        k_tau: [rad/(N m)] the model's torque gain (the rest residual is ``dq_err - k_tau tau``).

    Raises:
        IdentificationError: Fewer than ``min_samples`` at rest on either side of the torque reversal (the
            log has no hold where the torque changes sign: push the limb both ways while it holds).
    """
    dq_err, tau, dq = (np.asarray(x, dtype=float) for x in (dq_err, tau, dq))
    if not (dq_err.shape == tau.shape == dq.shape and dq_err.ndim == 1):
        raise IdentificationError(f"dq_err, tau, dq: shapes {dq_err.shape}, {tau.shape}, {dq.shape}: expected "
                                  "equal 1-D shapes")
    rest = np.isfinite(dq_err) & np.isfinite(tau) & (np.abs(dq) < dq_rest)
    pos, neg = rest & (tau > tau_min), rest & (tau < -tau_min)
    n_pos, n_neg = int(pos.sum()), int(neg.sum())
    if min(n_pos, n_neg) < min_samples:
        raise IdentificationError(f"{n_pos} samples at rest with tau > {tau_min} N m and {n_neg} with tau < "
                                  f"-{tau_min} N m: expected >= {min_samples} on each side (hold the joint while "
                                  "its torque is pushed through zero)")
    r = dq_err - k_tau * tau
    hi, lo = float(np.median(r[pos])), float(np.median(r[neg]))
    spread = float(np.median(np.abs(np.concatenate([r[pos] - hi, r[neg] - lo]))))
    return DeadBand(d=max(0.0, (hi - lo) / 2.0), offset=(hi + lo) / 2.0, n_positive=n_pos, n_negative=n_neg,
                    spread=spread)


def with_dead_band(model: MotorModel, d: float, band: float = BAND, provenance: str = "") -> MotorModel:
    """``model`` with its ``deadzone`` extra term replaced by the dead band ``d`` [rad] (shape ``band``,
    ``damping_share = 0``), first among the extra terms."""
    extra = {"deadzone": EffectTerm(float(d), {"band": float(band), "damping_share": 0.0})}
    extra.update({k: v for k, v in model.extra.items() if k != "deadzone"})
    return replace(model, extra=extra, provenance=provenance or model.provenance)


def needs(e: Excitation) -> str | None:
    """A torque, and a torque reversal at rest (:func:`rest_reversal`)."""
    return has_torque(e) if e.torque_range is None else rest_reversal(e)


def rest_reversal(e: Excitation) -> str | None:
    """A torque reversal at rest: without it a dead zone can look like Coulomb friction (only a look-alike's
    reason: the diagnosis tests the dead zone where Coulomb friction removes little, ``needs_lookalikes``)."""
    if e.torque_reversals_at_rest < 1:
        return ("the torque never changed sign while holding still: a dead zone looks like Coulomb friction; "
                "push the joint through zero torque at rest")
    return None


EFFECT = Effect(
    "deadzone", deadzone, grid, ("tau", "dq", "u", "u_v"),
    signature="residual against the linear prediction u: a step at u = 0 (the servo needs a minimum error); at rest "
    "with no effort, the sign of the last effort (the joint stays at the edge of the dead band it was pushed to); "
    "while the effort is near zero, the error follows the command's lead (the joint crosses the band freely)",
    family="servo_error",
    description="dead zone of the servo (on the position error or the current)",
    needs=needs,
    lookalike_needs=rest_reversal,
    needs_lookalikes=("coulomb",),
    fit_columns=columns,
    fold=fold,
    online=DeadzoneOnline,
    online_signals="tau, dq (history if v_th > 0: a latch of the sign of the last effort beyond the band); in the "
    "crossing form also q, q_des (history: the latch, the last command and the lead at the entry into the band)",
    confusable=("backlash", "coulomb"),
    shape_signals=shape_signals,
    experiments={
        "backlash": "reverse the torque at rest (a push through zero), then move fast against a constant load: a "
        "dead zone follows the sign of the servo error u, backlash the sign of the torque",
        "coulomb": "hold still and push the joint through zero torque: Coulomb friction vanishes at rest, a dead "
        "zone does not",
    },
    phi_unit="1",
)
