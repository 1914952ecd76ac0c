"""Excitation report: what the data exercised, so that an effect the data never excited is reported as
untestable, not as absent; and the requirements several effects share (each effect's ``needs`` in its file).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .signals import Signals

V_HOLD = 0.01  # [rad/s] below: holding still
V_MOVE = 0.05  # [rad/s] above: moving
V_SLOW = 0.25  # [rad/s] moving below this is slow motion
V_FAST = 0.3  # [rad/s] above: fast motion


@dataclass(frozen=True)
class Excitation:
    """What a log exercised (thresholds ``V_HOLD``, ``V_MOVE``, ``V_SLOW``, ``V_FAST`` in rad/s).

    Attributes:
        duration: Length of the log [s] (sample count times period if the time is known).
        n_samples: Number of samples.
        velocity_reversals: Changes of direction between moves faster than ``V_MOVE``.
        hold_time: Time with ``|dq| < V_HOLD`` [s].
        slow_time: Time with ``V_HOLD <= |dq| < V_SLOW`` [s].
        fast_time: Time with ``|dq| > V_FAST`` [s].
        quadrants: Fraction of the moving samples in each (velocity sign, torque sign) quadrant,
            keys ``"+,+"``, ``"+,-"``, ``"-,+"``, ``"-,-"`` (empty without torque).
        torque_range: Smallest and largest torque [N m] (None without torque).
        torque_reversals_at_rest: Sign changes of the torque while holding still: the command still if
            the log has one, else ``|dq| < V_HOLD`` (hysteresis 5 % of the largest ``|tau|``).
        torque_reversals: Sign changes of the torque anywhere (same hysteresis).
        loaded_motion: Fraction of the moving samples with ``|tau|`` above 30 % of its largest value.
        velocity_range: Smallest and largest velocity [rad/s].
        position_range: Smallest and largest position [rad] (None without position).
    """

    duration: float
    n_samples: int
    velocity_reversals: int
    hold_time: float
    slow_time: float
    fast_time: float
    quadrants: dict[str, float]
    torque_range: tuple[float, float] | None
    torque_reversals_at_rest: int
    torque_reversals: int
    loaded_motion: float
    velocity_range: tuple[float, float]
    position_range: tuple[float, float] | None

    def to_dict(self) -> dict:
        return asdict(self)

    def lines(self) -> list[str]:
        """Human-readable summary, one fact per line."""
        out = [
            f"duration {self.duration:.1f} s, {self.n_samples} samples",
            f"velocity reversals: {self.velocity_reversals} (moves faster than {V_MOVE} rad/s)",
            f"hold {self.hold_time:.1f} s, slow motion {self.slow_time:.1f} s, fast motion {self.fast_time:.1f} s",
            f"velocity range [{self.velocity_range[0]:.3g}, {self.velocity_range[1]:.3g}] rad/s",
        ]
        if self.torque_range is not None:
            quad = ", ".join(f"{k}: {100 * v:.0f} %" for k, v in self.quadrants.items())
            out += [
                f"torque range [{self.torque_range[0]:.3g}, {self.torque_range[1]:.3g}] N m, "
                f"{self.torque_reversals} sign changes, {self.torque_reversals_at_rest} at rest",
                f"quadrants (velocity sign, torque sign) of moving samples: {quad}",
                f"loaded motion (|tau| > 30 % of max while moving): {100 * self.loaded_motion:.0f} %",
            ]
        if self.position_range is not None:
            out.append(f"position range [{self.position_range[0]:.4g}, {self.position_range[1]:.4g}] rad")
        return out


def _reversals(x: np.ndarray, threshold: float) -> int:
    """Sign changes of ``x`` counting only excursions beyond ``threshold``."""
    s = np.where(x > threshold, 1, np.where(x < -threshold, -1, 0))
    s = s[s != 0]
    return int(np.count_nonzero(np.diff(s))) if s.size else 0


def excitation_report(signals: Signals) -> Excitation:
    """What ``signals`` exercised (``dq`` required, ``tau`` / ``q`` / ``t`` used when present)."""
    dq = signals["dq"]
    n = len(dq)
    dt = signals.dt or 0.0
    duration = n * dt
    speed = np.abs(dq)
    hold = speed < V_HOLD
    moving = speed > V_MOVE
    tau = signals["tau"] if "tau" in signals else None
    quadrants: dict[str, float] = {}
    torque_range = None
    rest_rev = rev = 0
    loaded = 0.0
    if tau is not None:
        torque_range = (float(tau.min()), float(tau.max()))
        peak = float(np.max(np.abs(tau))) or 1.0
        m = max(int(moving.sum()), 1)
        for sv, sn in ((1, "+"), (-1, "-")):
            for st, tn in ((1, "+"), (-1, "-")):
                sel = moving & (np.sign(dq) == sv) & (np.sign(tau) == st)
                quadrants[f"{sn},{tn}"] = float(np.count_nonzero(sel) / m)
        rev = _reversals(tau, 0.05 * peak)
        still = hold
        if "q_des" in signals:  # a hold is where the command holds still (the joint may creep in a dead band)
            still = np.abs(np.gradient(signals["q_des"])) < 1e-12
        rest_rev = _count_rest_reversals(tau, still, 0.05 * peak)
        loaded = float(np.count_nonzero(moving & (np.abs(tau) > 0.3 * peak)) / m)
    q = signals["q"] if "q" in signals else None
    return Excitation(
        duration=float(duration),
        n_samples=n,
        velocity_reversals=_reversals(dq, V_MOVE),
        hold_time=float(hold.sum() * dt),
        slow_time=float(np.count_nonzero(~hold & (speed < V_SLOW)) * dt),
        fast_time=float(np.count_nonzero(speed > V_FAST) * dt),
        quadrants=quadrants,
        torque_range=torque_range,
        torque_reversals_at_rest=rest_rev,
        torque_reversals=rev,
        loaded_motion=loaded,
        velocity_range=(float(dq.min()), float(dq.max())),
        position_range=None if q is None else (float(q.min()), float(q.max())),
    )


def _count_rest_reversals(tau: np.ndarray, hold: np.ndarray, threshold: float) -> int:
    """Torque sign changes inside runs of holding still."""
    count = 0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], hold.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        count += _reversals(tau[a:b], threshold)
    return count


# -- requirements shared by several effects: a reason string when the data cannot test the effect ------
def both_directions(e: Excitation) -> str | None:
    """Motion in both directions (at least two velocity reversals)."""
    if e.velocity_reversals < 2:
        return f"only {e.velocity_reversals} velocity reversals: expected motion in both directions (>= 2)"
    return None


def has_torque(e: Excitation) -> str | None:
    """A torque column."""
    return "no torque column" if e.torque_range is None else None


def fast_motion(e: Excitation) -> str | None:
    """At least 0.5 s of fast motion (the dynamics effects)."""
    if e.fast_time < 0.5:
        return f"fast motion {e.fast_time:.1f} s: expected >= 0.5 s faster than 0.3 rad/s (dynamics)"
    return None
