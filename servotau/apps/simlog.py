"""Identification logs from the simulated HRP-2 with hidden effects switched on (tests, demos, docs).

One joint of the hanging robot (default the right knee) follows a repeated excitation cycle; every
cycle holds the same mix, so that each cycle can be a held-out segment of the blocked cross-validation:

1. ``[0, 0.48 T)``: two sines (0.42 Hz and 1.25 Hz, amplitudes drawn per cycle) under a sin^2 window:
   velocity reversals at many speeds, up to about 1 rad/s, under a push of one sign (loaded motion).
2. ``[0.48 T, 0.80 T)``: hold under an operator push on the foot, a ramp to +F then a ramp to -F
   (high torque of both signs at zero velocity).
3. ``[0.80 T, T)``: a slow ramp out and back (about 0.1 rad/s) under a push of one sign, alternating
   from cycle to cycle (each quadrant of velocity sign and torque sign).

The log carries what a real robot would give, one row per tick as a controller logs it: the quantised
encoder ``q`` it read, the command ``q_des`` it sent, and a torque estimate ``tau`` = the joint torque
of that period delayed by ``tau_delay`` and with white noise ``tau_noise`` (the estimator). No velocity:
the workbench computes it by centred Savitzky-Golay differentiation, as on a real log. Ground truth
rides along in ``true/tau``, ``true/dq``, ``true/current`` and ``true/q`` (the link-side angle: the encoder
is on the motor side, so they differ by the gear's deflection on an elastic gear or one with play; an
experiment with a link-side angle sensor reads it), ignored by the workbench unless mapped, and the cycle
index in ``segment``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from servotau.errors import IdentificationError
from servotau.simrobot.scenario import OperatorPush
from servotau.simrobot.sim import SimConfig, SimRobot

log = logging.getLogger(__name__)

KNEE = "RLEG_JOINT3"


@dataclass(frozen=True)
class ExcitationPlan:
    """The repeated cycle of :mod:`simlog` (durations [s], amplitudes [rad], forces [N])."""

    cycles: int = 4
    cycle_s: float = 4.0  # [s]
    slow_amp: tuple[float, float] = (0.20, 0.28)  # [rad] range of the 0.42 Hz amplitude
    fast_amp: tuple[float, float] = (0.04, 0.08)  # [rad] range of the 1.25 Hz amplitude
    ramp_speed: float = 0.1  # [rad/s] slow ramp of phase 3
    push_force: float = 150.0  # [N] peak operator force on the foot (world x)
    push_body: str = "RLEG_FOOT"

    @property
    def seconds(self) -> float:
        return self.cycles * self.cycle_s


def simulate_log(
    effects: Mapping[str, Mapping[str, object]] | None = None,
    *,
    joint: str = KNEE,
    plan: ExcitationPlan | None = None,
    seed: int = 0,
    tau_delay: float = 0.002,  # [s] estimator delay on the torque
    tau_noise: float = 0.3,  # [N m] white noise on the torque estimate
    progress: Callable[[str], None] | None = None,
    base: SimConfig | None = None,
) -> dict[str, np.ndarray]:
    """Simulate one joint's identification log with ``effects`` hidden in the servo.

    Args:
        effects: Hidden effect -> parameters (see ``simrobot/servo_config.py`` EFFECT_PARAMS), applied to
            ``joint`` only; ``{"stribeck": {}}`` uses the simulator's defaults.
        joint: Joint to excite (the others hold their initial angle).
        plan: Excitation cycle (default :class:`ExcitationPlan`).
        seed: Seed of the simulator's sensor noise and of the excitation draws.
        tau_delay: Delay of the torque estimate [s].
        tau_noise: Standard deviation of the torque-estimate noise [N m].
        progress: Called with a short message every simulated second.
        base: The simulation's files (scenario, servo, sensors; default: the packaged hanging robot).

    Returns:
        Columns ``t`` [s], ``q`` [rad], ``q_des`` [rad], ``tau`` [N m], ``segment``, ``true/tau``,
        ``true/dq``, ``true/current``, ``true/q`` [rad] (link side), one row per 1 ms tick.
    """
    plan = plan or ExcitationPlan()
    overrides = {name: {**dict(params), "joints": [joint]} for name, params in (effects or {}).items()}
    base = base or SimConfig.named("hanging")
    robot = SimRobot(dataclasses.replace(base, effects=overrides or None, seed=seed))
    if joint not in robot.joint_names:
        raise IdentificationError(f"joint '{joint}': expected one of {list(robot.joint_names)}")
    j = robot.info.joint_index(joint)
    dt = robot.period
    rng = np.random.default_rng(seed + 1000)
    q0 = robot.read().q.copy()
    T = plan.cycle_s
    cycles = []
    for c in range(plan.cycles):
        start = c * T
        a1, a2 = rng.uniform(*plan.slow_amp), rng.uniform(*plan.fast_amp)
        phase = rng.uniform(0.0, 2.0 * math.pi)
        sgn = 1.0 if c % 2 == 0 else -1.0
        f = np.array([plan.push_force, 0.0, 0.0])
        hold = 0.16 * T
        robot.add_push(OperatorPush(plan.push_body, start + 0.48 * T, hold, sgn * f, np.zeros(3), "ramp"))
        robot.add_push(OperatorPush(plan.push_body, start + 0.64 * T, hold, -sgn * f, np.zeros(3), "ramp"))
        # half sine waves: smooth bumps of one sign while the joint swings, and while it ramps out and back
        robot.add_push(OperatorPush(plan.push_body, start, 0.48 * T, -sgn * 0.4 * f, np.zeros(3), "sine",
                                    frequency=0.5 / (0.48 * T)))
        robot.add_push(OperatorPush(plan.push_body, start + 0.80 * T, 0.2 * T, sgn * 0.6 * f, np.zeros(3), "sine",
                                    frequency=0.5 / (0.2 * T)))
        cycles.append((a1, a2, phase, sgn))
    n = int(round(plan.seconds / dt))
    out = {k: np.empty(n) for k in ("t", "q", "q_des", "true/tau", "true/dq", "true/current", "true/q", "segment")}
    q_cmd = q0.copy()
    g = robot.ground_truth()  # the state before the first step; then each step's truth is the next one's before
    for k in range(n):
        t = k * dt
        c = min(int(t // T), plan.cycles - 1)
        s = t - c * T
        a1, a2, phase, sgn = cycles[c]
        q_cmd[j] = q0[j] + _cycle_offset(s / T, T, a1, a2, phase, sgn, plan.ramp_speed)
        # One row per tick, as a controller logs it: the encoders it read, the command it sent, and the
        # torque the servo produced during that period.
        out["t"][k] = robot.time
        out["q"][k] = robot.read().q[j]
        out["true/dq"][k] = g.dq[j]
        out["true/q"][k] = g.q[j]
        out["q_des"][k] = q_cmd[j]
        robot.step(q_cmd)
        g = robot.ground_truth()
        out["true/tau"][k] = g.tau[j]
        out["true/current"][k] = g.current[j]
        out["segment"][k] = c
        if progress is not None and (k + 1) % int(round(1.0 / dt)) == 0:
            progress(f"simulated {robot.time:.0f} / {plan.seconds:.0f} s")
    shift = int(round(tau_delay / dt))
    tau = np.concatenate([np.full(shift, out["true/tau"][0]), out["true/tau"][: n - shift]])
    out["tau"] = tau + tau_noise * rng.standard_normal(n)
    return out


def _cycle_offset(x: float, T: float, a1: float, a2: float, phase: float, sgn: float, speed: float) -> float:
    """Command offset [rad] at the fraction ``x`` in [0, 1) of a cycle of ``T`` seconds."""
    if x < 0.48:
        s = x * T
        window = math.sin(math.pi * x / 0.48) ** 2
        return window * (a1 * math.sin(2 * math.pi * 0.42 * s) + a2 * math.sin(2 * math.pi * 1.25 * s + phase))
    if x < 0.80:
        return 0.0
    s = (x - 0.80) * T  # out and back, peak velocity `speed`, smooth at both ends
    half = 0.1 * T
    amp = 2.0 * half * speed / math.pi
    return sgn * amp * (1.0 - math.cos(math.pi * s / half)) / 2.0
