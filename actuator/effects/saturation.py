"""``saturation``: current limit: past it the servo torque no longer follows the position error.

``phi = [sat] (lead(t) - lead(t_onset))`` where it has the sign of the proxy ``tau + beta dq`` (else 0):
saturated while the motor-torque proxy ``|tau + beta dq|`` exceeds ``tau_sat`` [N m] (until it falls below
``release tau_sat``); ``lead = q_des(t - 1 tick) - q(t)``, its change since the onset of the limit is the integral
of the command's lead the servo cannot close (the measured error since the onset: the term resets the model to the
error measured when the limit was reached), and it grows in the direction of the torque. ``beta``
[N m s/rad] is the damping outside the servo; the proxy reads the signals, not ``u`` (a fit on saturated data
bends the model). Simulated knee, 2.5 A limit, fast excitation: held-out gain 0.97, fall 0.98, coefficient 1.0
(docs/workbench.md); coefficients outside ``SATURATION_COEFFICIENT`` are not chosen.

On-line: ``tau``, ``dq``, ``q``, ``q_des`` (history: the limit detector's state, the last command, the lead at the
onset). It reads the commands of the previous ticks only (past the limit the command does not set the torque):
its term does not change with this tick's command.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, has_torque
from ..registry import Effect
from ..signals import Signals, command_lead, hysteresis, sample_lead, since_onset

ORDER = 110
LEVELS = (0.7, 0.8, 0.9, 0.95, 0.97, 0.99)  # quantiles of the proxy: the limit may hold up to 30 % of a log
DAMPING = (0.0, 0.5, 1.0, 1.5, 2.0)  # beta in units of the data's P99 |tau| / P99 |dq|
RELEASE = 0.8  # leave the limit when the proxy falls below 80 % of it
SATURATION_COEFFICIENT = (0.5, 1.5)
"""The part of the command's lead the error keeps past the limit: 1 in theory, with the same margin of 0.5 on
both sides for a bent fit. Below half, the servo still closes most of the lead where the detector fires: it is
not at a limit (fitted 0.13 on a simulated log with Stribeck friction and thermal drift, no limit); outside
the range the term is a generic memory correction (fitted -1.5 and -2.0 on simulated logs without a limit)."""


def motor_torque_proxy(s: Signals | Mapping[str, float], beta: float) -> np.ndarray | float:
    """``tau + beta dq`` [N m]: the torque estimate plus the damping outside the servo (``beta`` [N m s/rad]),
    what the motor must produce; it sits at the current limit while the servo saturates. Read from the
    signals only, not from the model: a model fitted on saturated data is bent by them."""
    return s["tau"] + beta * s["dq"]


def saturation(s: Signals, tau_sat: float, beta: float, release: float = 0.8) -> np.ndarray:
    """The error's growth since the current limit was reached [rad], zero below the limit.

    Saturated: ``|tau + beta dq| > tau_sat`` [N m], held until it falls to ``release tau_sat`` (hysteresis:
    the proxy is noisy at the limit). Past the limit the servo torque no longer follows the error: the
    command's lead that the servo cannot close integrates, ``phi = lead(t) - lead(t_onset)`` with
    ``lead = q_des(t - 1) - q(t)`` (:func:`~servotau.actuator.signals.command_lead`). This is the measured
    error since the onset: the term resets the model to the error it measured when the limit was reached
    (output-error form). The servo asks for more torque than the limit gives, so the error grows in the
    direction of the torque: where ``phi`` has the other sign the servo is back in its linear range, and
    ``phi = 0`` (a term of either sign would fit any error where the torque is large, e.g. friction while
    holding a load).
    """
    proxy = motor_torque_proxy(s, beta)
    flag = hysteresis(np.abs(proxy), tau_sat, release * tau_sat, s.starts)
    grown = since_onset(command_lead(s), flag, s.starts)
    return np.where(grown * proxy > 0.0, grown, 0.0)


def grid(s: Signals) -> tuple[dict[str, float], ...]:
    """Thresholds at high quantiles of the motor-torque proxy ``|tau + beta dq|`` [N m] (the limit is where it
    piles up), for damping ``beta`` [N m s/rad] scaled by the data (its 99th percentiles of torque and
    velocity)."""
    dq99 = float(np.quantile(np.abs(s["dq"]), 0.99))
    scale = float(np.quantile(np.abs(s["tau"]), 0.99)) / dq99 if dq99 > 0 else 0.0
    out = []
    for f in DAMPING if scale > 0 else (0.0,):
        beta = float(f"{f * scale:.3g}")
        levels = np.quantile(np.abs(motor_torque_proxy(s, beta)), LEVELS)
        out += [{"tau_sat": float(f"{v:.4g}"), "beta": beta, "release": RELEASE} for v in levels]
    return tuple(out)


class SaturationOnline:
    """On-line ``saturation``: the limit detector's state, the last command and the lead at the onset."""

    def __init__(self, shape: Mapping[str, float], period: float):
        self.tau_sat, self.beta = shape["tau_sat"], shape["beta"]
        self.release = shape.get("release", RELEASE)
        self.saturated = False
        self.q_des_prev: float | None = None  # [rad] the command of the last tick
        self.onset_lead = 0.0  # [rad]

    def _saturated(self, x: Mapping[str, float]) -> bool:
        level = self.release * self.tau_sat if self.saturated else self.tau_sat
        return abs(motor_torque_proxy(x, self.beta)) > level

    def value(self, x: Mapping[str, float]) -> float:
        if not (self.saturated and self._saturated(x)):
            return 0.0  # below the limit, or its onset (this tick's command is not read)
        grown = sample_lead(x, self.q_des_prev) - self.onset_lead
        return grown if grown * motor_torque_proxy(x, self.beta) > 0.0 else 0.0  # in the torque's direction

    def commit(self, x: Mapping[str, float]) -> None:
        sat = self._saturated(x)
        if sat and not self.saturated:
            self.onset_lead = sample_lead(x, self.q_des_prev)
        self.saturated = sat
        self.q_des_prev = x["q_des"]


def needs(e: Excitation) -> str | None:
    return has_torque(e)


EFFECT = Effect(
    "saturation", saturation, grid, ("q", "q_des", "tau", "dq"),
    signature="large residuals of one sign where the motor-torque proxy |tau + beta dq| sits at its largest values "
    "(the current limit), growing with the command's lead over the joint while it stays there",
    family="servo_error",
    description="current limit: past it the servo torque no longer follows the position error, which "
    "integrates the command's lead the servo cannot close",
    needs=needs,
    online=SaturationOnline,
    history=True,
    online_signals="tau, dq, q, q_des (history: the limit detector's state, the last command, the lead at the onset)",
    coefficient_range=SATURATION_COEFFICIENT,
    phi_unit="rad",
)
